#!/usr/bin/env bash
# Set up .venv if needed, then run the chapter. Extra arguments go to scale_data.py, run in the folder
# this was called from: a relative path among them (--out, --pusht_data) is the caller's, as with any command.
set -euo pipefail
caller=$PWD
# the repository is where this script really lives: a link to it (in ~/bin) is followed, link by link
script=${BASH_SOURCE[0]}
while [ -L "$script" ]; do
    target=$(readlink "$script")
    case $target in
        /*) script=$target ;;
        *) script=$(dirname "$script")/$target ;;
    esac
done
repo=$(cd -P "$(dirname "$script")" && pwd)
source "$repo/setup_env.sh"  # it works in the repository (cd there)
cd "$caller"
exec "$repo/.venv/bin/python" "$repo/scale_data.py" "$@"
