#!/usr/bin/env bash
# Mission soak (issue: mission scale): a long simulated mission
# (simulate_flight --scenario mission, scenery generated along a 7 km path)
# replayed at RATE times real time through launch/replay.launch, with one
# subscriber on every map output as rviz and a planner would have
# (bench/scripts/soak_monitor.py), sampling each second the manager's resident
# memory, the bytes each output carried and the nodelets' diagnostics. Writes
# OUT_DIR/soak.csv, OUT_DIR/soak.png (figures over time), OUT_DIR/summary.md
# and the map saved at shutdown. Assumes scripts/build.sh has run.
#
#   DURATION_S=1800 (the flight's length)  RATE=2  OUT_DIR=build/soak  ROS_PORT=11393
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
ws="${WS:-$repo/build/ws}"
duration="${DURATION_S:-1800}"
rate="${RATE:-2}"
out="${OUT_DIR:-$repo/build/soak}"
port="${ROS_PORT:-11393}"
export PATH="/usr/bin:$PATH"
for p in python3-matplotlib python3-diagnostic-msgs; do
  dpkg -s "$p" > /dev/null 2>&1 || apt-get install -y -qq "$p" > /dev/null 2>&1
done
mkdir -p "$out"
out="$(cd "$out" && pwd)"  # roslaunch runs its nodes in ~/.ros: no relative paths
bin="$ws/devel/lib/stereo_occupancy"

bag="$out/mission_${duration}s.bag"
if [ ! -f "$bag" ]; then
  echo "simulating a ${duration} s mission into $bag ..."
  "$bin/simulate_flight" --scenario mission --duration-s "$duration" --output "$bag.tmp" 2> "$out/simulate.log"
  mv "$bag.tmp" "$bag"
  mv "$bag.tmp.scene.txt" "$bag.scene.txt"
fi

set +u
# shellcheck disable=SC1091
source "$ws/devel/setup.bash"
set -u
export ROS_MASTER_URI="http://localhost:$port"
map_dir="$out/map"
rm -rf "$map_dir"
mkdir -p "$map_dir"
roscore -p "$port" > "$out/roscore.log" 2>&1 &
core=$!
monitor=""
trap 'kill $monitor $launch $core 2>/dev/null || true; wait 2>/dev/null || true' EXIT
for _ in $(seq 50); do rosparam list > /dev/null 2>&1 && break; sleep 0.2; done
echo "replaying at ${rate}x through launch/replay.launch (log: $out/launch.log) ..."
roslaunch stereo_occupancy replay.launch bag:="$bag" rate:="$rate" save_dir:="$map_dir" delay_s:=5 \
  > "$out/launch.log" 2>&1 &
launch=$!
manager=""
for _ in $(seq 100); do
  manager="$(pgrep -f 'nodelet manager __name:=stereo_occupancy_manager' | head -n 1 || true)"
  [ -n "$manager" ] && break
  sleep 0.1
done
[ -n "$manager" ] || { echo "the nodelet manager did not start; see $out/launch.log"; exit 1; }
/usr/bin/python3 "$repo/bench/scripts/soak_monitor.py" "$out/soak.csv" "$manager" 2> "$out/monitor.log" &
monitor=$!
wait $launch || true  # replay.launch ends with the bag (the accumulator saves the map on shutdown)
kill -INT $monitor 2>/dev/null || true
wait $monitor 2>/dev/null || true

/usr/bin/python3 - "$out" "$map_dir" "$duration" "$rate" <<'PY'
import csv, glob, math, os, sys
import matplotlib
matplotlib.use('Agg')
import matplotlib.pyplot as plt
out, map_dir, duration, rate = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
rows = list(csv.DictReader(open(f'{out}/soak.csv')))
t = [float(r['t_s']) for r in rows]
col = lambda k: [float(r[k]) for r in rows]
byte_cols = [k for k in rows[0] if k.endswith('_bytes')]
out_mb_s = [sum(float(r[k]) for k in byte_cols) / 1e6 for r in rows]
fig, ax = plt.subplots(4, 1, figsize=(9, 11), sharex=True)
ax[0].plot(t, col('rss_mib')); ax[0].set_ylabel('manager RSS [MiB]')
ax[1].plot(t, col('fusion_p50_ms'), label='fusion p50'); ax[1].plot(t, col('fusion_p99_ms'), label='fusion p99')
ax[1].plot(t, col('mapper_p50_ms'), label='mapper p50'); ax[1].plot(t, col('mapper_p99_ms'), label='mapper p99')
ax[1].set_ylabel('per update / image [ms]'); ax[1].legend(loc='upper left')
ax[2].plot(t, out_mb_s); ax[2].set_ylabel('map outputs [MB/s]')
ax[3].plot(t, col('updates_received'), label='updates received'); ax[3].plot(t, col('updates_lost'), label='lost')
ax[3].set_ylabel('updates'); ax[3].legend(loc='upper left'); ax[3].set_xlabel('wall time of the replay [s]')
fig.suptitle(f'{duration:.0f} s mission at {rate:g}x real time')
fig.tight_layout(); fig.savefig(f'{out}/soak.png', dpi=80)
finite = lambda v: [x for x in v if not math.isnan(x)]
pct = lambda v, q: sorted(v)[min(len(v) - 1, int(q * len(v)))] if v else float('nan')
last = rows[-1]
maps = sorted(glob.glob(f'{map_dir}/*.bt') + glob.glob(f'{map_dir}/*.ot') + glob.glob(f'{map_dir}/*.db'))
with open(f'{out}/summary.md', 'w') as f:
    f.write(f'| figure | value |\n|---|---:|\n')
    f.write(f'| replay wall time [s] | {t[-1]:.0f} |\n')
    f.write(f'| images processed | {last["images_processed"]} |\n')
    f.write(f'| updates received / lost / refused | {last["updates_received"]} / {last["updates_lost"]} / {last["updates_refused"]} |\n')
    rss = finite(col('rss_mib'))
    f.write(f'| manager RSS first / max / last [MiB] | {rss[0]:.0f} / {max(rss):.0f} / {rss[-1]:.0f} |\n')
    f.write(f'| fusion p50 / p99 of the per-second p99 [ms] | {pct(finite(col("fusion_p50_ms")), 0.5):.2f} / {pct(finite(col("fusion_p99_ms")), 0.99):.2f} |\n')
    slow = sum(1 for v in finite(col('fusion_p99_ms')) if v > 100.0)
    f.write(f'| seconds with a fusion p99 over 100 ms | {slow} of {len(rows)} |\n')
    flight = [r for r in rows if float(r['updates_received'] or 0) < float(last['updates_received'])] or rows
    f.write(f'| manager RSS max while mapping [MiB] | {max(finite([float(r["rss_mib"]) for r in flight])):.0f} |\n')
    f.write(f'| mapper p50 / p99 of the per-second p99 [ms] | {pct(finite(col("mapper_p50_ms")), 0.5):.2f} / {pct(finite(col("mapper_p99_ms")), 0.99):.2f} |\n')
    f.write(f'| map outputs mean / max [MB/s] | {sum(out_mb_s) / len(out_mb_s):.2f} / {max(out_mb_s):.2f} |\n')
    for k in byte_cols:
        f.write(f'| {k[:-6]} mean [MB/s] | {sum(col(k)) / len(rows) / 1e6:.3f} |\n')
    for m in maps:
        f.write(f'| {os.path.basename(m)} on disk [MB] | {os.path.getsize(m) / 1e6:.1f} |\n')
print(open(f'{out}/summary.md').read())
PY
echo "soak: $out/soak.csv, $out/soak.png, $out/summary.md"
