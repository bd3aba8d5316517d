#!/usr/bin/env sh
# One entry point: sets up ./.venv (Python 3.11, pinned versions) and runs a job.
#   ./run.sh          main job: the seed paper's tables next to ours, then the headless Blender
#                     pipeline on the default example scene
#   ./run.sh test     every test (core, stress, real Blender), then ruff
#   ./run.sh bench    benchmarks; regenerates BENCHMARKS.md and its plots
set -eu
cd "$(dirname "$0")"

python=${PYTHON:-python3.11}
venv=.venv

setup() {
    # (re)install when a requirements file changed since the last install
    stamp="$venv/.installed-$(cat "$@" | cksum | cut -d' ' -f1)"
    if [ ! -x "$venv/bin/python" ]; then
        "$python" -c 'import sys; assert sys.version_info[:2] == (3, 11), "Python 3.11 is required"' \
            || { echo "run.sh: needs Python 3.11 (set PYTHON=/path/to/python3.11)" >&2; exit 1; }
        "$python" -m venv "$venv"
    fi
    if [ ! -e "$stamp" ]; then
        for file in "$@"; do
            "$venv/bin/python" -m pip install --disable-pip-version-check -q -r "$file"
        done
        rm -f "$venv"/.installed-*
        touch "$stamp"
    fi
}

job=${1:-main}
[ $# -gt 0 ] && shift
case "$job" in
    main)
        setup requirements.txt
        "$venv/bin/python" -m benchmarks.seed_tables
        if [ -f addon/headless.py ] && [ -f blender_scenes/03_cornell_box.blend ]; then
            "$venv/bin/python" -m addon.headless blender_scenes/03_cornell_box.blend \
                --out build/03_cornell_box_lit.blend --render build/03_cornell_box.png
        fi
        ;;
    test)
        setup requirements.txt
        "$venv/bin/python" -m pytest -q "$@"
        "$venv/bin/ruff" check .
        ;;
    bench)
        setup requirements.txt requirements-bench.txt
        "$venv/bin/python" -m benchmarks.run_all "$@"
        ;;
    *)
        echo "usage: ./run.sh [main|test|bench] [args...]" >&2
        exit 2
        ;;
esac
