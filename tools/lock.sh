#!/usr/bin/env bash
# Regenerate environment.lock from pyproject.toml (runtime + dev + docs extras), every package pinned.
#   bash tools/lock.sh        (needs pip-tools: python -m pip install pip-tools)
# pip-compile pins the CPU wheel it finds as torch==2.13.0+cpu; the lock keeps the plain
# torch==2.13.0, which on these machines installs that same CPU build.
set -euo pipefail
cd "$(dirname "$0")/.."
tmp=$(mktemp)
# start from the current pins: pip-compile keeps every pin that still satisfies pyproject.toml
cp environment.lock "$tmp"
pip-compile --quiet --extra dev --extra docs --strip-extras --allow-unsafe \
  --no-emit-index-url --no-emit-find-links --no-emit-trusted-host \
  --output-file "$tmp" pyproject.toml
{
  echo "# environment.lock: exact pins of every package of the book's environment."
  echo "# Regenerate with: bash tools/lock.sh   (pip-compile from pyproject.toml, see that script)"
  sed -e 's/^torch==\([0-9.]*\)+cpu$/torch==\1/' -e "s#--output-file=[^ ]*#--output-file=environment.lock#" "$tmp"
} > environment.lock
rm -f "$tmp"
grep -q '^torch==2.13.0$' environment.lock || { echo "torch is not pinned to 2.13.0" >&2; exit 1; }
echo "environment.lock: $(grep -c '==' environment.lock) pins"
