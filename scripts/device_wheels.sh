#!/usr/bin/env bash
# Fetch, here, the wheels a lent GPU machine lacks (its image has jax, flax, optax, orbax and
# chex, not tyro) into .whl/ for scripts/device_env.sh; name .whl in the call's carry.
set -euo pipefail
cd "$(dirname "$0")/.."
grep -qx '/.whl/' .git/info/exclude 2>/dev/null || echo '/.whl/' >> "$(git rev-parse --git-dir)/info/exclude"
python -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    --platform manylinux2014_x86_64 -d .whl tyro==1.0.17 shtab==1.13.0 typeguard==4.6.1 docstring_parser==0.18.0
ls .whl
