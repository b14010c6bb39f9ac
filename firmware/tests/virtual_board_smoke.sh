#!/bin/sh
# Smoke test: virtual_board rejects bad input and announces its pty for a valid capture.
set -eu
VB="$1"
T=$(mktemp -d)
trap 'if [ "$PID" -gt 0 ]; then kill "$PID" 2>/dev/null || true; fi; rm -rf "$T"' EXIT
PID=0
# an invalid file: exit status 2
printf 'not a capture' > "$T/bad.lhcap"
if "$VB" --capture "$T/bad.lhcap" > /dev/null 2>&1; then echo "accepted a bad file"; exit 1; fi
# a valid one-record capture: header + 1 record + CRC, built with python3 if present
if ! command -v python3 > /dev/null; then echo "python3 missing: partial smoke test"; exit 0; fi
python3 - "$T/ok.lhcap" <<'PY'
import struct, sys, zlib
hdr = b"LHCP" + struct.pack("<HHIIIIQQI", 1, 108, 2000000, 0, 7, 0x100, 0, 10, 1)
hdr += struct.pack("<32h", *range(32))
body = hdr + struct.pack("<II", 0, 5)
open(sys.argv[1], "wb").write(body + struct.pack("<I", zlib.crc32(body)))
PY
"$VB" --capture "$T/ok.lhcap" > "$T/out" &
PID=$!
i=0
while [ ! -s "$T/out" ] && [ $i -lt 50 ]; do sleep 0.1; i=$((i+1)); done
P=$(head -n 1 "$T/out")
case "$P" in /dev/pts/*) [ -e "$P" ] && echo "virtual_board serves on $P"; exit 0 ;; esac
echo "no pty path printed: '$P'"; exit 1
