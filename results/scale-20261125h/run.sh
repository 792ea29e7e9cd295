#!/bin/bash
# 2-D DMDA program on 1 and 2 ranks with the 2-D coarse V-cycle at GAMG threshold 0.02 (2026-11-25, commit 7dd9e34).
exec "$(dirname "$0")/../scale-20261124b/run.sh" results/scale-20261125h "2 512 3" "2 1024 2" "2 2048 1"
