"""Per case and commit of ab.txt (ab.sh's output): HTPPC's range and median ms, ICC(0)'s range, and the median of
HTPPC's ms beyond ICC(0)'s in the same run. From the repository root:
  python results/small-20261128/summary.py results/small-20261128/ab.txt > results/small-20261128/summary.txt"""
import collections
import re
import statistics
import sys

runs = collections.defaultdict(list)
for line in open(sys.argv[1]):
    m = re.match(r"(\S+) run \d+: (\S+) (\d+) rows: HTPPC ([\d.]+) ms \((\d+)\), ICC\(0\) ([\d.]+) ms", line)
    if m:
        commit, name, _, htp, _, icc = m.groups()
        runs[(name, commit)].append((float(htp), float(icc)))
for (name, commit), v in runs.items():
    htp, icc = [h for h, _ in v], [i for _, i in v]
    print(f"{name} {commit}: HTPPC {min(htp):.2f}-{max(htp):.2f} (median {statistics.median(htp):.2f}) ms, ICC(0) "
          f"{min(icc):.2f}-{max(icc):.2f} ms, HTPPC beyond ICC(0) median {statistics.median(h - i for h, i in v):.2f} ms")
