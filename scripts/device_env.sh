# Source this at the start of a command on a lent GPU machine (the `device` tool's run):
#   source scripts/device_env.sh || exit
# It finds the Python that holds jax there (the image keeps it in /opt/torch/.venv; a
# symlink named python to it would lose the venv, so `python` becomes a small wrapper),
# installs the wheels carried in .whl/ (tyro and its needs, absent there; fetch them here
# with scripts/device_wheels.sh and name .whl in the call's carry) into /tmp/site, and sets
# what three processes sharing one GPU need. It prints what it found, so a call that goes
# wrong later still says which stack it ran on.
for candidate in /opt/torch/.venv/bin/python3 /opt/*/.venv/bin/python3 "$(command -v python3)" /usr/bin/python3; do
    if [ -x "$candidate" ] && "$candidate" -c "import jax" 2>/dev/null; then DEVICE_PYTHON="$candidate"; break; fi
done
if [ -z "${DEVICE_PYTHON:-}" ]; then echo "device_env: no python with jax found" >&2; return 1; fi
if ls .whl/*.whl >/dev/null 2>&1; then
    "$DEVICE_PYTHON" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || return 1
    export PYTHONPATH="/tmp/site:$PWD${PYTHONPATH:+:$PYTHONPATH}"
else
    export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"
fi
mkdir -p /tmp/device_bin
printf '#!/bin/sh\nexec %s "$@"\n' "$DEVICE_PYTHON" > /tmp/device_bin/python
chmod +x /tmp/device_bin/python
export PATH="/tmp/device_bin:$PATH" XLA_PYTHON_CLIENT_PREALLOCATE=false PYTHONUNBUFFERED=1
python -c "import jax, flax, optax, orbax.checkpoint, tyro; print('device_env:', jax.__version__, flax.__version__, optax.__version__, tyro.__version__, jax.devices())" || return 1
