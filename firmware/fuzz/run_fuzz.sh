#!/usr/bin/env bash
# Fuzz the board's protocol parser with libFuzzer (clang), for a bounded time.
#   bash firmware/fuzz/run_fuzz.sh [SECONDS] [--update-corpus]
# Builds into build/firmware-fuzz, fuzzes from the kept corpus (firmware/tests/corpus) plus
# fresh seeds, and with --update-corpus merges what it found back into the kept corpus
# (minimised by libFuzzer's -merge; ctest replays that corpus as a regression test).
set -euo pipefail
SECONDS_TO_RUN="${1:-30}"
UPDATE="${2:-}"
HERE="$(cd "$(dirname "$0")" && pwd)"
FW="$(dirname "$HERE")"
ROOT="$(dirname "$FW")"
OUT="$ROOT/build/firmware-fuzz"
KEEP="$FW/tests/corpus"
mkdir -p "$OUT/work" "$OUT/seeds" "$KEEP"
CC="${CC:-clang}"
if ! command -v "$CC" > /dev/null; then
    echo "run_fuzz.sh: $CC not found (apt-get install -y clang)" >&2
    exit 1
fi
"$CC" -std=c11 -g -O1 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined \
    -I"$FW/core/include" "$FW"/core/src/*.c "$FW/tests/fuzz_proto.c" -o "$OUT/fuzz_proto"
python3 "$HERE/make_seeds.py" "$OUT/seeds"
"$OUT/fuzz_proto" -max_total_time="$SECONDS_TO_RUN" -max_len=160 -timeout=5 \
    -print_final_stats=1 "$OUT/work" "$KEEP" "$OUT/seeds"
if [ "$UPDATE" = "--update-corpus" ]; then
    rm -rf "$OUT/merged" && mkdir -p "$OUT/merged"
    # edge coverage only (no hit counters): keeps the corpus to a few dozen files
    "$OUT/fuzz_proto" -merge=1 -use_counters=0 -max_len=160 "$OUT/merged" "$KEEP" "$OUT/seeds" "$OUT/work"
    rm -f "$KEEP"/*
    cp "$OUT/merged"/* "$KEEP"/
    echo "kept corpus: $(ls "$KEEP" | wc -l) files in $KEEP"
fi
