#!/usr/bin/env bash
# Adds RGL measurements to the rgl_reader corpus, and full-size MERL tables to the merl_reader
# corpus. A valid MERL table is 34,992,012 bytes, too big to commit, and byte mutation never
# grows a small seed into one, so without these files the fuzzer only ever reaches the header
# and size checks. The tables are written by the `nbrdf` CLI
# (analytic fits tabulated on the MERL grid) as corpus/merl_reader/generated-*.binary, which
# .gitignore leaves out. Idempotent: existing tables are kept.
#
# Usage: nbrdf-core/fuzz/seed.sh        (NBRDF=path/to/nbrdf to use another build of the CLI)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)

# RGL seeds: the small synthetic measurements (committed; rewritten identically) and, where the
# shared data is present, the real measurements (git-ignored as generated-*).
python3 "$here/make_rgl_seeds.py" "$here/corpus/rgl_reader"
shared=${NBRDF_SHARED:-$root/../shared}
for real in "$shared"/data/rgl/*_rgb.bsdf; do
    seed=$here/corpus/rgl_reader/generated-$(basename "$real")
    if [ -f "$real" ] && [ ! -s "$seed" ]; then
        cp "$real" "$seed"
    fi
done

nbrdf=${NBRDF:-$root/target/release/nbrdf}
if [ ! -x "$nbrdf" ]; then
    echo "seed.sh: no nbrdf CLI at $nbrdf: build it first (make setup, or cargo build --release" \
        "at the repository root), or set NBRDF=path/to/nbrdf" >&2
    exit 1
fi
out=$here/corpus/merl_reader
mkdir -p "$out"
# Two models and materials: different values and different cells marked not measured.
for spec in "sgd gold-metallic-paint" "abc blue-metallic-paint"; do
    read -r model material <<<"$spec"
    table=$out/generated-$model-$material.binary
    if [ ! -s "$table" ]; then
        "$nbrdf" synth --model "$model" --material "$material" -o "$table"
    fi
done
