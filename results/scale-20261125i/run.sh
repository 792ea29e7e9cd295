#!/bin/bash
# 3-D DMDA program on 1 and 2 ranks after the memory and analysis changes (2026-11-25, commit 62332e1).
exec "$(dirname "$0")/../scale-20261124b/run.sh" results/scale-20261125i "3 64 2" "3 128 1"
