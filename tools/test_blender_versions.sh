#!/usr/bin/env bash
# The add-on's compatibility tests (tests marked `compat` in tests/python/test_blender.py) on
# each Blender version given as BPY:PYTHON (e.g. 5.3.0:3.13), each in its own venv
# (.venv-bpy-BPY, made on first use with the Python that bpy is built for) with the core the
# default venv built (an abi3 module, on sys.path from python/).
#
# The versions run at once, each into out/compat-BPY.log, printed in order when all are
# done: a run is mostly single-threaded (pip unpacking bpy, Blender starting and syncing
# scenes), so on 2 cores three runs side by side take about half as long as one after
# another. Exit status: non-zero if any version failed.
set -u
cd "$(dirname "$0")/.."
mkdir -p out
pids=() specs=()
for spec in "$@"; do
    bpy=${spec%%:*} pyv=${spec##*:} venv=.venv-bpy-${spec%%:*}
    log=out/compat-$bpy.log
    (
        py=$(tools/python_for.sh "$pyv") || { echo "Python $pyv not found: bpy $bpy needs it (pyenv install $pyv)"; exit 1; }
        if [ ! -e "$venv/.deps-stamp" ]; then
            "$py" -m venv "$venv" && "$venv/bin/python" -m pip install -q --upgrade pip &&
                "$venv/bin/python" -m pip install -q --no-compile "bpy==$bpy" pyoidn==2.5.1.0 OpenEXR pytest &&
                touch "$venv/.deps-stamp" || exit 1
        fi
        # (each Blender its own user resources and pytest its own temporary root)
        PYTHONPATH="$PWD/python" VIRTUAL_ENV="$PWD/$venv" PATH="$PWD/$venv/bin:$PATH" \
            BLENDER_USER_RESOURCES="$PWD/out/blender-user-$bpy" \
            "$venv/bin/python" -m pytest -q -m compat -p no:cacheprovider --basetemp="out/compat-tmp-$bpy" \
            tests/python/test_blender.py
    ) > "$log" 2>&1 &
    pids+=($!) specs+=("$spec")
done
status=0
for i in "${!pids[@]}"; do
    spec=${specs[$i]}
    if wait "${pids[$i]}"; then result=passed; else result=FAILED; status=1; fi
    echo "Blender ${spec%%:*} (Python ${spec##*:}): $result"
    cat "out/compat-${spec%%:*}.log"
done
exit $status
