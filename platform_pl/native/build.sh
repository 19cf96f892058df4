#!/usr/bin/env bash
# Compiles the platform's foreign libraries (each NAME.c here into NAME.so beside it) with
# SWI-Prolog's swipl-ld, when the .so is missing or older than its source. Safe to run again.
# The platform runs without them, slower (see bulk_write.pl and float_vectors.pl).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
for src in "$here"/*.c; do
    lib="${src%.c}.so"
    if [ ! -f "$lib" ] || [ "$src" -nt "$lib" ]; then
        tmp="$lib.$$.tmp"
        swipl-ld -shared -O2 -Wall -o "$tmp" "$src"
        mv -f "$tmp" "$lib"             # atomic: a process loading it never sees half a file
        printf '[build] %s\n' "$(basename "$lib")" >&2
    fi
done
