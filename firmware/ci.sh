#!/usr/bin/env bash
# Firmware CI: host build + unit tests + fuzz-corpus replay, the corpus replayed again under
# AddressSanitizer + UndefinedBehaviorSanitizer, then the STM32F429 cross build.
#   bash firmware/ci.sh        (from the repository root or anywhere)
# Installs what it needs with apt-get when missing (needs root, as on the project's CI).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT="$(pwd)"

need=()
command -v cmake > /dev/null || need+=(cmake)
command -v make > /dev/null || need+=(make)
command -v cc > /dev/null || need+=(gcc libc6-dev)
command -v python3 > /dev/null || need+=(python3)
command -v arm-none-eabi-gcc > /dev/null || need+=(gcc-arm-none-eabi)
[ -d /usr/lib/arm-none-eabi/newlib ] || need+=(libnewlib-arm-none-eabi)
# clang for the fuzz smoke: its sanitizer/fuzzer runtime is a separate package on Debian
command -v clang > /dev/null || need+=(clang)
apt_install() {
    echo "firmware/ci.sh: installing $*"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "$@" > /dev/null
}
if [ "${#need[@]}" -gt 0 ]; then
    apt_install "${need[@]}"
fi
# checked once clang is there (a fresh machine gets clang above without its runtime)
if ! echo 'int LLVMFuzzerTestOneInput(const char *d, long n){return 0;}' \
        | clang -x c -fsanitize=fuzzer,address -o /dev/null - > /dev/null 2>&1; then
    apt_install "libclang-rt-$(clang -dumpversion | cut -d. -f1)-dev"
fi

echo "== host build (build/firmware-host)"
cmake -S firmware -B build/firmware-host -DCMAKE_BUILD_TYPE=RelWithDebInfo > /dev/null
cmake --build build/firmware-host -j2 > /dev/null
echo "== host tests"
ctest --test-dir build/firmware-host --output-on-failure

echo "== fuzz corpus under ASan/UBSan (build/firmware-asan)"
mkdir -p build/firmware-asan
SAN_CC="$(command -v cc)" # gcc: libasan/libubsan come with it
"$SAN_CC" -std=c11 -g -O1 -fsanitize=address,undefined -fno-sanitize-recover=all \
    -fno-omit-frame-pointer -Ifirmware/core/include firmware/core/src/*.c \
    firmware/tests/fuzz_proto.c firmware/tests/fuzz_replay_main.c \
    -o build/firmware-asan/fuzz_proto_replay
python3 firmware/fuzz/make_seeds.py build/firmware-asan/seeds
ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    build/firmware-asan/fuzz_proto_replay firmware/tests/corpus
ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    build/firmware-asan/fuzz_proto_replay build/firmware-asan/seeds

echo "== cross build (build/firmware-arm)"
cmake -S firmware -B build/firmware-arm \
    -DCMAKE_TOOLCHAIN_FILE="$ROOT/firmware/cmake/arm-none-eabi.cmake" \
    -DCMAKE_BUILD_TYPE=MinSizeRel > /dev/null
cmake --build build/firmware-arm -j2 > /dev/null
echo "== image size"
arm-none-eabi-size -A build/firmware-arm/target/stm32f429/lhgraph-board.elf \
    | grep -E '^(section|\.isr_vector|\.text|\.data|\.bss|\.noinit|\.ccm|\.sdram) '
arm-none-eabi-size build/firmware-arm/target/stm32f429/lhgraph-board.elf

# a few seconds of fuzzing when clang is there (never updates the kept corpus)
if command -v clang > /dev/null && [ "${LHB_CI_FUZZ_SECONDS:-5}" -gt 0 ]; then
    echo "== fuzz smoke (${LHB_CI_FUZZ_SECONDS:-5} s)"
    bash firmware/fuzz/run_fuzz.sh "${LHB_CI_FUZZ_SECONDS:-5}" > build/fuzz-smoke.log 2>&1 \
        || { tail -40 build/fuzz-smoke.log; exit 1; }
    grep -E 'stat::number_of_executed_units' build/fuzz-smoke.log || true
fi
echo "firmware/ci.sh: OK"
