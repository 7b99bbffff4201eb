#!/usr/bin/env bash
# usage: bash tools/same_bytes.sh OUT
# A refactor's proof that it keeps the bytes: small source sets of every task (gen_demos.py --task T
# --episodes 2 --seed 0) and each grown in every mode (augment_demos.py --per_demo 2, one worker, small
# perturbations), then OUT/sha.txt: the sha256 of every file under their data/ and meta/ (reports and stamps
# aside). Run it in a checkout before and after the change and diff the two sha.txt files.
set -euo pipefail
[ $# -eq 1 ] || { echo "error: usage: bash tools/same_bytes.sh OUT (a new folder)" >&2; exit 2; }
[ ! -e "$1" ] || { echo "error: $1 exists; give a new folder" >&2; exit 2; }
out=$(mkdir -p "$1" && cd "$1" && pwd)
cd "$(dirname "$0")/.."
py=.venv/bin/python
for t in ${TASKS:-pusht aloha gym_pusht pusher aloha_transfer_cube aloha_insertion}; do
  sigma="--pos_sigma 0.02 --yaw_sigma 0.1"  # m, rad: small moves, so that replays keep some
  [ "$t" = gym_pusht ] && sigma="--pos_sigma 0.01 --yaw_sigma 0.1"
  $py gen_demos.py --task "$t" --episodes 2 --seed 0 --quiet --no-video --out "$out/src_$t" >/dev/null
  for m in resolve replay replay_live; do
    $py augment_demos.py --src "$out/src_$t" --out "$out/${t}_$m" --per_demo 2 --workers 1 --aug_mode $m \
      $sigma --quiet > "$out/${t}_$m.log" 2>&1 || echo "$t $m: exit $?" >> "$out/failed.txt"
  done
done
(cd "$out" && find . \( -path '*/data/*' -o -path '*/meta/*' \) -type f | sort | xargs sha256sum) > "$out/sha.txt"
echo "$(wc -l < "$out/sha.txt") files hashed: $out/sha.txt"
