cd "$(dirname "$0")/../.."  # the checkout
PY=.venv/bin/python
for seed in 61 62 63 64; do
  $PY -m engine.cli synth /tmp/i23/r$seed-all.laz --seed $seed --rooms 4 --density 1500 --overwrite --workers 1 > /dev/null 2>&1
  $PY - $seed <<'PYEOF'
import sys, laspy, numpy as np
s = sys.argv[1]
las = laspy.read(f"/tmp/i23/r{s}-all.laz")
g = np.asarray(las.gt_space); cls = np.asarray(las.gt_class)
ids, n = np.unique(g[g > 0], return_counts=True)
room = int(ids[np.argmax(n)])
for v, keep in (("", g == room), ("-crop", (g == room) & ~np.isin(cls, [0, 1]))):
    out = laspy.LasData(las.header); out.points = las.points[keep]
    out.write(f"/tmp/i23/r{s}{v}.laz")
    print(s, "room", room, v or "whole", int(keep.sum()), "points")
PYEOF
  for v in "" "-crop"; do
    $PY -m engine.cli ingest /tmp/i23/r$seed$v.laz /tmp/i23/r$seed$v.zarr --overwrite --workers 1 > /dev/null 2>&1
    echo "== r$seed$v"; $PY -m engine.cli spaces /tmp/i23/r$seed$v.zarr --workers 1 2>&1 | grep -v "tasks ("
  done
done
