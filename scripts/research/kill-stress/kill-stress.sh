#!/usr/bin/env bash
# Kills a logging `skinflow run` with SIGKILL N times, each at a random moment 0.1-1.6 s after
# its file appears, and counts the files `skinflow inspect` opens and refuses.
#
# usage: kill-stress.sh SKINFLOW N [LOGGER_PARAMS]
#   SKINFLOW       the skinflow binary
#   N              number of killed runs
#   LOGGER_PARAMS  extra hdf5_logger params, e.g. 'deflate_level = 1' or 'swmr = true'
# Prints "kills=N readable=R refused=F" and the refusals, grouped; RANDOM is seeded (1) so a
# rerun picks the same kill moments (the runs themselves are not deterministic).
set -euo pipefail
BIN=$(realpath "$1"); N=$2; EXTRA=${3:-}
HERE=$(cd "$(dirname "$0")" && pwd)
W=$(mktemp -d /tmp/kill-stress.XXXXXX)
cd "$W"
# A calibration protocol long enough that no run ends before its kill: 6 x 6 sites, 4 forces.
sed -e 's/n = \[3, 3\]/n = [6, 6]/' "$HERE/../../../tests/fixtures/tiny-calibration.toml" > scene.toml
cat > g.toml <<TOML
[[node]]
id = "skin"
kind = "sim"
params = { scene = "scene.toml", pacing = "fast" }
[[node]]
id = "pace"
kind = "sync"
[[node]]
id = "log"
kind = "hdf5_logger"
params = { path = "crash.h5", flush_interval_s = 0.02${EXTRA:+, $EXTRA} }
[[edge]]
from = "skin.eit"
to = "log.eit"
capacity = 4096
[[edge]]
from = "skin.pressure"
to = "log.pressure"
capacity = 4096
[[edge]]
from = "skin.truth"
to = "log.truth"
capacity = 4096
[[edge]]
from = "skin.eit"
to = "pace.eit"
TOML
"$BIN" check g.toml >/dev/null
RANDOM=1
readable=0; refused=0
for _ in $(seq 1 "$N"); do
  rm -f crash.h5 .crash.h5.*
  "$BIN" run g.toml >/dev/null 2>&1 &
  pid=$!
  while [ ! -e crash.h5 ]; do sleep 0.01; done
  ms=$(( RANDOM % 1500 + 100 ))
  sleep "$(printf '%d.%03d' $((ms / 1000)) $((ms % 1000)))"
  kill -KILL "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
  if out=$("$BIN" inspect crash.h5 2>&1); then
    readable=$((readable + 1))
  else
    refused=$((refused + 1)); echo "$out" | head -1 >> refused.log
  fi
done
echo "kills=$N readable=$readable refused=$refused (${EXTRA:-defaults}; work dir $W)"
[ -f refused.log ] && sort refused.log | uniq -c
exit 0
