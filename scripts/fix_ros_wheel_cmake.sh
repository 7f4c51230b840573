#!/usr/bin/env bash
# The Jazzy wheels ship CMake export files that point at the wheel builder's Python
# (/opt/python/cp311-cp311/...). Point them at this venv's Python and numpy headers so
# rosidl_generate_interfaces can build our message package. Idempotent.
set -euo pipefail
: "${VIRTUAL_ENV:?activate the venv first}"
pyinc=$(python -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
npinc=$(python -c 'import numpy; print(numpy.get_include())')
[ -f "$pyinc/Python.h" ] || { echo "no Python.h in $pyinc (Debian: apt-get install python3.11-dev)" >&2; exit 1; }
n=0
while IFS= read -r f; do
  sed -i -E \
    -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/lib/python3\.[0-9]+/site-packages/numpy/_?core/include#${npinc}#g" \
    -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/include/python3\.[0-9]+#${pyinc}#g" "$f"
  n=$((n+1))
done < <(grep -rlE '/opt/python/cp3[0-9]+-cp3[0-9]+' "$VIRTUAL_ENV/share" --include='*.cmake' || true)
echo "fix_ros_wheel_cmake: fixed $n file(s)"
if grep -rqE '/opt/python/' "$VIRTUAL_ENV/share" --include='*.cmake'; then
  echo "fix_ros_wheel_cmake: /opt/python paths remain" >&2; exit 1
fi
