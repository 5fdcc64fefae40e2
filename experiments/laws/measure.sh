#!/bin/sh
# Measures learning from simulated logs of the retina laws of this folder:
#   experiments/laws/measure.sh SAMPLES STARTS METHOD LAW...
# For every law: a log of SAMPLES babbled samples (smspace simulate), the true sensory
# sets through its first STARTS samples (smspace trace on the agent), the learned sets
# through the same starts (smspace learn --method METHOD --truth-sets), and one line
# per law: held-out error, rank, sets traced, median / 90th set error, seconds.
# SMSPACE (the binary) and OUT (the work folder) may be set; 2 threads. PERIOD gives
# the motors' periods to smspace learn when they are not all hinges (pupil.toml:
# PERIOD=2pi,2pi,2pi,2pi,0.5:1.5). POINTS (default 100) samples every set; kernels of
# dimension 2 or more need several hundred for the comparison to resolve 0.05 rad.
set -eu
samples=$1; starts=$2; method=$3; shift 3
points=${POINTS:-100}
bin=${SMSPACE:-target/release/smspace}
out=${OUT:-/tmp/smspace-laws}
export RAYON_NUM_THREADS=${RAYON_NUM_THREADS:-2}
here=$(dirname "$0")
for law in "$@"; do
    d=$out/$law-$samples
    mkdir -p "$d"
    if [ ! -f "$d/log/motors.npy" ]; then
        "$bin" simulate --agent "$here/$law.toml" --n "$samples" --out-dir "$d/log" 2>/dev/null
    fi
    if [ "$points" != 100 ]; then starts_tag=$starts-p$points; else starts_tag=$starts; fi
    if [ ! -f "$d/truth-$starts_tag.npy" ]; then
        python3 "$here/first_rows.py" "$d/log/motors.npy" "$starts" "$d/starts-$starts.npy"
        "$bin" trace --agent "$here/$law.toml" --env "$d/log/environment.json" \
            --motors "$d/starts-$starts.npy" --method sensory --points "$points" \
            --out "$d/truth-$starts_tag.npy" 2>/dev/null
    fi
    t0=$(date +%s.%N)
    "$bin" learn --motors "$d/log/motors.npy" --sensors "$d/log/sensors.npy" \
        --starts "$d/starts-$starts.npy" --method "$method" --points "$points" \
        ${PERIOD:+--period "$PERIOD"} \
        --truth-sets "$d/truth-$starts_tag.npy" --out "$d/$method-$starts_tag.npy" \
        > "$d/$method-$starts_tag.log" 2>&1 || true
    t1=$(date +%s.%N)
    python3 - "$d" "$method" "$starts_tag" "$law" "$t0" "$t1" <<'PY'
import json, sys
d, method, starts, law, t0, t1 = sys.argv[1:]
try:
    r = json.load(open(f"{d}/{method}-{starts}.law.json"))
    e = json.load(open(f"{d}/{method}-{starts}.errors.json"))
    t = json.load(open(f"{d}/{method}-{starts}.trace.json"))
except OSError:
    print(f"| {law} | failed: see {d}/{method}-{starts}.log |")
    sys.exit()
log = r["logs"][0]
inv = r.get("invariants") or {}
noise = (log.get("noise") or {}).get("relative_overall", float("nan"))
rank = r["rank"]
if r.get("data_rank", {}).get("rank", rank) != rank:
    rank = f"{rank} (data {r['data_rank']['rank']})"
summary = t["summary"]
print(f"| {law} | {log['held_out_relative_rms']:.3f} | {noise:.4f} | {rank} | {inv.get('invariants', '-')} "
      f"| {summary['traced']} / {summary['total']} | {e['median']:.3f} / {e['p90']:.3f} | {float(t1) - float(t0):.0f} |")
PY
done
