#!/usr/bin/env bash
# The package as a user gets it: builds dfrl's wheel, checks that it holds every file git tracks
# under the package's folders, installs it into a fresh virtual environment outside the checkout
# and runs `dfrl demo` from there (the platform's foreign libraries compiled on first use into a
# fresh cache). CI runs it after the tests; run it yourself after changing what is packaged.
# Extra arguments go to `dfrl demo`. Needs the package registry (or pip's cache) for the
# dependencies.
set -euo pipefail
. "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
cd "$DFRL_ROOT"
say() { printf '[wheel] %s\n' "$*" >&2; }

work="$(mktemp -d "${TMPDIR:-/tmp}/dfrl-wheel.XXXXXX")"
trap 'rm -rf "$work" "$DFRL_ROOT/build"' EXIT
rm -rf "$DFRL_ROOT/build"        # setuptools' staging folder: a stale copy would be shipped

say "building the wheel"
python -m pip wheel -q --no-deps -w "$work/dist" "$DFRL_ROOT"
wheel="$(ls "$work"/dist/dfrl-*.whl)"
say "built $(basename "$wheel") ($(du -k "$wheel" | cut -f1) kB)"

if git -C "$DFRL_ROOT" rev-parse --git-dir >/dev/null 2>&1; then
    python - "$wheel" <<'PY'
import subprocess, sys, zipfile
roots = ["dfrl", "platform_pl", "pybridge", "robots", "arenas", "experiments"]
tracked = subprocess.run(["git", "ls-files", "--", *roots], check=True, text=True,
                         capture_output=True).stdout.split()
want = {p.removeprefix("dfrl/") for p in tracked if not p.endswith(".gitignore")}
with zipfile.ZipFile(sys.argv[1]) as z:
    have = {n.removeprefix("dfrl/") for n in z.namelist() if n.startswith("dfrl/")}
missing, extra = sorted(want - have), sorted(have - want)
for p in missing:
    print(f"[wheel] missing from the wheel: {p}", file=sys.stderr)
for p in extra:
    print(f"[wheel] in the wheel but not tracked by git: {p}", file=sys.stderr)
if missing or extra:
    sys.exit(1)
print(f"[wheel] the wheel holds the {len(want)} files git tracks, and nothing else",
      file=sys.stderr)
PY
fi

say "installing it into a fresh virtual environment"
python3 -m venv "$work/venv"
"$work/venv/bin/python" -m pip install -q "$wheel"
mkdir -p "$work/run"
cd "$work/run"
if env -u PYTHONPATH -u VIRTUAL_ENV DFRL_NATIVE_CACHE="$work/native" \
        "$work/venv/bin/python" -c 'import dfrl, sys; sys.exit("dfrl imported from " + dfrl.__file__ if not dfrl.__file__.startswith(sys.prefix) else 0)'; then
    :
else
    say "the installed dfrl is not the one imported"; exit 1
fi
say "running dfrl demo from $work/run"
env -u PYTHONPATH -u VIRTUAL_ENV PATH="$work/venv/bin:/usr/local/bin:/usr/bin:/bin" \
    DFRL_NATIVE_CACHE="$work/native" "$work/venv/bin/dfrl" demo "$@"
built="$(find "$work/native" -name '*.so' | wc -l)"
if [ "$built" -lt 4 ]; then
    say "the platform's foreign libraries were not built on first use ($built of 4)"; exit 1
fi
if find "$work/venv" -name '*.so' -path '*dfrl*' | grep -q .; then
    say "a compiled library was written inside site-packages"; exit 1
fi
say "ok: the wheel installs, dfrl demo exits 0, the 4 foreign libraries were built in the cache"
