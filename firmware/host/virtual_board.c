/* virtual_board: the board core on a pseudo-terminal instead of the USART.
 *
 *   virtual_board --capture FILE.lhcap [options]
 *
 * Prints the path to open (the pty, or --link) as the first line of stdout and serves the
 * capture over the link protocol until killed. ARM "captures" by replaying the file's port
 * words through the same edge extractor the board uses, spread over the requested duration
 * (times --time-scale), so a download returns the file byte for byte. A version-2 file's IMU
 * records are added as the replay reaches their sample index (as the board's data-ready
 * interrupt adds them), and its missed-sample count is reproduced.
 *
 * Fault injection (board -> host direction): --drop-every N drops every Nth byte sent,
 * --flip-every N flips one bit of every Nth byte sent, --disconnect-after-blocks N closes the
 * pty after N READ responses and opens a new one (--link keeps a stable path, like a
 * /dev/serial/by-id link; --disconnects K times, each N blocks after the last reconnect),
 * --rx-drop-every / --rx-flip-every do the same to the bytes the board receives, --baud B paces the output at B baud (10 bits per byte). */
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "lhb/capture.h"
#include "lhb/config.h"
#include "lhb/crc32.h"
#include "lhb/endian.h"
#include "lhb/errors.h"
#include "lhb/lhcap.h"
#include "lhb/proto.h"

typedef struct {
    const char *capture_path;
    const char *link_path;
    uint32_t block_size;
    double baud;
    double time_scale;
    uint64_t drop_every;
    uint64_t flip_every;
    uint64_t rx_drop_every;
    uint64_t rx_flip_every;
    uint32_t disconnect_after;
    uint32_t disconnects;
    uint32_t reconnect_delay_ms;
    bool verbose;
} options_t;

typedef struct {
    int master;
    int slave_keep; /* our own slave fd: keeps the pty alive while the host has it closed */
    char slave_name[256];
} pty_t;

static volatile sig_atomic_t g_stop = 0;
static options_t g_opt;
static pty_t g_pty;
static uint64_t g_tx_bytes;
static uint64_t g_rx_bytes;
static double g_wire_time; /* when the paced wire becomes free (s, monotonic) */

/* source capture (the file) */
static lhcap_header_t g_hdr;
static uint32_t *g_src;  /* 2 u32 per record */
static uint32_t g_src_n;
static uint32_t *g_imu;  /* LHB_IMU_WORDS u32 per IMU record (index, then 6 raw i16) */
static uint32_t g_imu_n;

/* replay state */
static bool g_sampling;
static double g_sampling_t0;
static uint32_t g_fed;   /* samples fed so far */
static uint32_t g_rec;   /* current source record */
static uint32_t g_imu_next; /* next IMU record to add */

static lhb_capture_t g_cap;
static lhb_proto_t g_proto;

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static double g_t0;

static uint32_t now_ms(void)
{
    return (uint32_t)((now_s() - g_t0) * 1000.0);
}

static void sleep_s(double s)
{
    if (s <= 0) {
        return;
    }
    struct timespec ts;
    ts.tv_sec = (time_t)s;
    ts.tv_nsec = (long)((s - (double)ts.tv_sec) * 1e9);
    while (nanosleep(&ts, &ts) != 0 && errno == EINTR && !g_stop) {
    }
}

static void on_signal(int sig)
{
    (void)sig;
    g_stop = 1;
}

static void die(const char *what)
{
    fprintf(stderr, "virtual_board: %s: %s\n", what, strerror(errno));
    exit(1);
}

static int pty_open(pty_t *p)
{
    p->master = posix_openpt(O_RDWR | O_NOCTTY);
    if (p->master < 0 || grantpt(p->master) != 0 || unlockpt(p->master) != 0) {
        return -1;
    }
    const char *name = ptsname(p->master);
    if (name == NULL || strlen(name) >= sizeof p->slave_name) {
        return -1;
    }
    strcpy(p->slave_name, name);
    p->slave_keep = open(p->slave_name, O_RDWR | O_NOCTTY);
    if (p->slave_keep < 0) {
        return -1;
    }
    struct termios tio;
    if (tcgetattr(p->slave_keep, &tio) != 0) {
        return -1;
    }
    cfmakeraw(&tio);
    if (tcsetattr(p->slave_keep, TCSANOW, &tio) != 0) {
        return -1;
    }
    if (g_opt.link_path != NULL) {
        char tmp[4096];
        snprintf(tmp, sizeof tmp, "%s.tmp%ld", g_opt.link_path, (long)getpid());
        unlink(tmp);
        if (symlink(p->slave_name, tmp) != 0 || rename(tmp, g_opt.link_path) != 0) {
            return -1;
        }
    }
    return 0;
}

static void pty_close(pty_t *p)
{
    if (p->slave_keep >= 0) {
        close(p->slave_keep);
    }
    if (p->master >= 0) {
        close(p->master);
    }
    p->slave_keep = -1;
    p->master = -1;
}

static void write_all(const uint8_t *d, size_t n)
{
    while (n > 0 && !g_stop) {
        ssize_t w = write(g_pty.master, d, n);
        if (w < 0) {
            if (errno == EINTR || errno == EAGAIN) {
                continue;
            }
            return; /* link gone: the bytes are lost, as on a real cable */
        }
        d += w;
        n -= (size_t)w;
    }
}

/* Output path of the board: fault injection and pacing, then the pty. */
static void tx_bytes(void *ctx, const uint8_t *data, size_t n)
{
    (void)ctx;
    uint8_t chunk[256];
    size_t k = 0;
    for (size_t i = 0; i < n; i++) {
        uint8_t b = data[i];
        g_tx_bytes++;
        if (g_opt.drop_every != 0 && g_tx_bytes % g_opt.drop_every == 0) {
            continue;
        }
        if (g_opt.flip_every != 0 && g_tx_bytes % g_opt.flip_every == 0) {
            b ^= (uint8_t)(1u << ((g_tx_bytes / g_opt.flip_every) % 8u));
        }
        chunk[k++] = b;
        if (k == sizeof chunk || i + 1 == n) {
            if (g_opt.baud > 0) {
                double t = now_s();
                if (g_wire_time < t - 0.002) {
                    g_wire_time = t; /* the wire was idle; small lags (sleep jitter) are caught up */
                }
                sleep_s(g_wire_time - t);
                g_wire_time += (double)k * 10.0 / g_opt.baud;
            }
            write_all(chunk, k);
            k = 0;
        }
    }
    if (k > 0) {
        write_all(chunk, k);
    }
}

/* --- the "hardware": replay of the file's samples ------------------------------------- */

static int hw_start(void *ctx, uint32_t n)
{
    (void)ctx;
    (void)n;
    g_sampling = true;
    g_sampling_t0 = now_s();
    g_fed = 0;
    g_rec = 0;
    g_imu_next = 0;
    for (uint32_t k = 0; k < g_hdr.imu_missed; k++) {
        lhb_capture_imu_missed(&g_cap);
    }
    return 0;
}

/* IMU records stamped before sample `end`: added while their samples are being taken */
static void replay_imu(uint32_t end)
{
    while (g_imu_next < g_imu_n && g_imu[LHB_IMU_WORDS * g_imu_next] < end) {
        const uint32_t *w = g_imu + LHB_IMU_WORDS * g_imu_next;
        int16_t raw[6];
        for (unsigned k = 0; k < 3; k++) {
            raw[2 * k] = (int16_t)(uint16_t)w[1 + k];
            raw[2 * k + 1] = (int16_t)(uint16_t)(w[1 + k] >> 16);
        }
        (void)lhb_capture_add_imu(&g_cap, w[0], raw);
        g_imu_next++;
    }
}

static void hw_stop(void *ctx)
{
    (void)ctx;
    g_sampling = false;
}

static void replay_step(void)
{
    if (!g_sampling) {
        return;
    }
    uint32_t total = (uint32_t)g_hdr.capture_samples;
    double wall = (double)g_cap.duration_ms / 1000.0 * g_opt.time_scale;
    double frac = wall <= 0 ? 1.0 : (now_s() - g_sampling_t0) / wall;
    uint32_t due = frac >= 1.0 ? total : (uint32_t)(frac * (double)total);
    static uint32_t buf[4096];
    while (g_sampling && g_fed < due) {
        uint32_t n = due - g_fed;
        if (n > 4096u) {
            n = 4096u;
        }
        for (uint32_t i = 0; i < n; i++) {
            uint32_t s = g_fed + i;
            while (g_rec + 1u < g_src_n && g_src[2u * (g_rec + 1u)] <= s) {
                g_rec++;
            }
            buf[i] = g_src[2u * g_rec + 1u];
        }
        replay_imu(g_fed + n);
        g_fed += n;
        if (lhb_capture_feed(&g_cap, buf, n)) {
            g_sampling = false; /* as the DMA interrupt does on the board */
        }
    }
}

/* --- loading and checking the capture file -------------------------------------------- */

static void load_fail(const char *why)
{
    fprintf(stderr, "virtual_board: %s: %s\n", g_opt.capture_path, why);
    exit(2);
}

static void load_capture(void)
{
    FILE *f = fopen(g_opt.capture_path, "rb");
    if (f == NULL) {
        die(g_opt.capture_path);
    }
    if (fseek(f, 0, SEEK_END) != 0) {
        die(g_opt.capture_path);
    }
    long size = ftell(f);
    rewind(f);
    if (size < (long)(LHCAP_HEADER_LEN + LHCAP_RECORD_LEN + LHCAP_TRAILER_LEN) ||
        size > 0x7FFFFFFFL) {
        load_fail("size is not that of a capture");
    }
    uint8_t *buf = malloc((size_t)size);
    if (buf == NULL || fread(buf, 1, (size_t)size, f) != (size_t)size) {
        die(g_opt.capture_path);
    }
    fclose(f);
    if (lhcap_header_unpack(buf, (size_t)size, &g_hdr) != LHB_OK) {
        load_fail("not a .lhcap header of version 1 (108 bytes) or 2 (128 bytes), or unknown "
                  "flags or IMU part");
    }
    uint32_t header_len = lhcap_header_len(g_hdr.version);
    uint64_t want = header_len + (uint64_t)LHCAP_RECORD_LEN * g_hdr.n_records +
                    (uint64_t)LHCAP_IMU_RECORD_LEN * g_hdr.n_imu + LHCAP_TRAILER_LEN;
    if (want != (uint64_t)size || g_hdr.n_records == 0) {
        load_fail("file size disagrees with the record count");
    }
    if (lhb_crc32(buf, (size_t)size - 4) != lhb_get_le32(buf + size - 4)) {
        load_fail("CRC-32 mismatch");
    }
    g_src_n = g_hdr.n_records;
    g_src = malloc(sizeof(uint32_t) * 2u * g_src_n);
    if (g_src == NULL) {
        die("malloc");
    }
    for (uint32_t i = 0; i < g_src_n; i++) {
        const uint8_t *r = buf + header_len + (size_t)LHCAP_RECORD_LEN * i;
        g_src[2u * i] = lhb_get_le32(r);
        g_src[2u * i + 1u] = lhb_get_le32(r + 4);
        if (i == 0 ? g_src[0] != 0
                   : (g_src[2u * i] <= g_src[2u * i - 2u] || g_src[2u * i + 1u] == g_src[2u * i - 1u])) {
            load_fail("edge records break the format rules (index order / repeated word)");
        }
    }
    if (g_hdr.capture_samples <= g_src[2u * (g_src_n - 1u)] ||
        g_hdr.capture_samples > 0xFFFFFFFFull) {
        load_fail("capture length in samples is not past the last record (or > 2^32-1)");
    }
    g_imu_n = g_hdr.n_imu;
    g_imu = malloc(sizeof(uint32_t) * LHB_IMU_WORDS * (g_imu_n + 1u));
    if (g_imu == NULL) {
        die("malloc");
    }
    const uint8_t *imu = buf + header_len + (size_t)LHCAP_RECORD_LEN * g_src_n;
    for (uint32_t i = 0; i < g_imu_n; i++) {
        for (unsigned k = 0; k < LHB_IMU_WORDS; k++) {
            g_imu[LHB_IMU_WORDS * i + k] = lhb_get_le32(imu + LHCAP_IMU_RECORD_LEN * i + 4u * k);
        }
        if ((i > 0 && g_imu[LHB_IMU_WORDS * i] <= g_imu[LHB_IMU_WORDS * (i - 1u)]) ||
            g_imu[LHB_IMU_WORDS * i] >= g_hdr.capture_samples) {
            load_fail("IMU records break the format rules (index order / past the capture)");
        }
    }
    free(buf);
}

/* --- main ------------------------------------------------------------------------------- */

static void usage(void)
{
    fprintf(stderr,
            "usage: virtual_board --capture FILE.lhcap [--link PATH] [--block-size N]\n"
            "         [--baud B] [--time-scale X] [--drop-every N] [--flip-every N]\n"
            "         [--rx-drop-every N] [--rx-flip-every N]\n"
            "         [--disconnect-after-blocks N] [--disconnects K] [--reconnect-delay-ms MS]\n"
            "         [--verbose]\n");
    exit(2);
}

static unsigned long long parse_uint(const char *opt, const char *s, unsigned long long max)
{
    char *end = NULL;
    errno = 0;
    unsigned long long v = strtoull(s, &end, 10);
    if (errno != 0 || end == s || *end != '\0' || v > max || s[0] == '-') {
        fprintf(stderr, "virtual_board: %s: not an integer in 0..%llu: %s\n", opt, max, s);
        exit(2);
    }
    return v;
}

static double parse_double(const char *opt, const char *s)
{
    char *end = NULL;
    double v = strtod(s, &end);
    if (end == s || *end != '\0' || !(v >= 0.0) || v > 1e12) {
        fprintf(stderr, "virtual_board: %s: not a non-negative number: %s\n", opt, s);
        exit(2);
    }
    return v;
}

static void parse_args(int argc, char **argv)
{
    g_opt.block_size = LHB_BLOCK_SIZE_DEFAULT;
    g_opt.time_scale = 1.0;
    g_opt.disconnects = 1;
    g_opt.reconnect_delay_ms = 300;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        const char *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (strcmp(a, "--verbose") == 0) {
            g_opt.verbose = true;
            continue;
        }
        if (v == NULL) {
            usage();
        }
        i++;
        if (strcmp(a, "--capture") == 0) {
            g_opt.capture_path = v;
        } else if (strcmp(a, "--link") == 0) {
            g_opt.link_path = v;
        } else if (strcmp(a, "--block-size") == 0) {
            g_opt.block_size = (uint32_t)parse_uint(a, v, LHB_BLOCK_SIZE_MAX);
            if (g_opt.block_size == 0) {
                usage();
            }
        } else if (strcmp(a, "--baud") == 0) {
            g_opt.baud = parse_double(a, v);
        } else if (strcmp(a, "--time-scale") == 0) {
            g_opt.time_scale = parse_double(a, v);
        } else if (strcmp(a, "--drop-every") == 0) {
            g_opt.drop_every = parse_uint(a, v, UINT64_MAX);
        } else if (strcmp(a, "--flip-every") == 0) {
            g_opt.flip_every = parse_uint(a, v, UINT64_MAX);
        } else if (strcmp(a, "--rx-drop-every") == 0) {
            g_opt.rx_drop_every = parse_uint(a, v, UINT64_MAX);
        } else if (strcmp(a, "--rx-flip-every") == 0) {
            g_opt.rx_flip_every = parse_uint(a, v, UINT64_MAX);
        } else if (strcmp(a, "--disconnect-after-blocks") == 0) {
            g_opt.disconnect_after = (uint32_t)parse_uint(a, v, UINT32_MAX);
        } else if (strcmp(a, "--disconnects") == 0) {
            g_opt.disconnects = (uint32_t)parse_uint(a, v, 1000);
        } else if (strcmp(a, "--reconnect-delay-ms") == 0) {
            g_opt.reconnect_delay_ms = (uint32_t)parse_uint(a, v, 60000);
        } else {
            usage();
        }
    }
    if (g_opt.capture_path == NULL) {
        usage();
    }
    if (g_opt.disconnect_after != 0 && g_opt.link_path == NULL) {
        fprintf(stderr, "virtual_board: --disconnect-after-blocks needs --link PATH\n");
        exit(2);
    }
}

int main(int argc, char **argv)
{
    parse_args(argc, argv);
    load_capture();
    g_t0 = now_s();

    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);

    /* the core: template = the file's header, exact sample count, storage for its records */
    lhb_hw_t hw = {hw_start, hw_stop, NULL};
    uint32_t *storage = malloc(sizeof(uint32_t) * 2u * g_src_n);
    if (storage == NULL) {
        die("malloc");
    }
    lhb_capture_init(&g_cap, &hw, storage, g_src_n, &g_hdr);
    uint32_t *imu_storage = malloc(sizeof(uint32_t) * LHB_IMU_WORDS * (g_imu_n + 1u));
    if (imu_storage == NULL) {
        die("malloc");
    }
    lhb_capture_set_imu(&g_cap, imu_storage, g_imu_n);
    g_cap.fixed_samples = (uint32_t)g_hdr.capture_samples;
    g_cap.fixed_start_time = true;
    lhb_proto_init(&g_proto, &g_cap, g_opt.block_size, tx_bytes, NULL);
    static lhb_diag_t diag = {.selftest = LHB_ST_NOT_RUN}; /* no hardware to test */
    g_proto.diag = &diag;

    g_pty.master = g_pty.slave_keep = -1;
    if (pty_open(&g_pty) != 0) {
        die("pty");
    }
    printf("%s\n", g_opt.link_path != NULL ? g_opt.link_path : g_pty.slave_name);
    fflush(stdout);
    if (g_opt.verbose) {
        fprintf(stderr, "virtual_board: %s, %u records, %llu samples, pty %s\n",
                g_opt.capture_path, g_src_n, (unsigned long long)g_hdr.capture_samples,
                g_pty.slave_name);
    }

    uint32_t disconnects_done = 0;
    uint32_t blocks_at_connect = 0; /* --disconnect-after-blocks counts from each (re)connect */
    uint8_t rx[512];
    while (!g_stop) {
        struct pollfd pfd = {g_pty.master, POLLIN, 0};
        int pr = poll(&pfd, 1, g_sampling ? 1 : 5);
        if (pr < 0 && errno != EINTR) {
            die("poll");
        }
        if (pr > 0 && (pfd.revents & POLLIN) != 0) {
            ssize_t n = read(g_pty.master, rx, sizeof rx);
            if (n > 0) {
                size_t k = 0; /* faults on the host -> board direction */
                for (ssize_t i = 0; i < n; i++) {
                    uint8_t b = rx[i];
                    g_rx_bytes++;
                    if (g_opt.rx_drop_every != 0 && g_rx_bytes % g_opt.rx_drop_every == 0) {
                        continue;
                    }
                    if (g_opt.rx_flip_every != 0 && g_rx_bytes % g_opt.rx_flip_every == 0) {
                        b ^= (uint8_t)(1u << ((g_rx_bytes / g_opt.rx_flip_every) % 8u));
                    }
                    rx[k++] = b;
                }
                lhb_proto_rx(&g_proto, rx, k, now_ms());
            }
        }
        replay_step();
        lhb_capture_poll(&g_cap, now_ms());
        if (g_opt.disconnect_after != 0 && disconnects_done < g_opt.disconnects &&
            g_proto.blocks_sent - blocks_at_connect >= g_opt.disconnect_after) {
            disconnects_done++;
            if (g_opt.verbose) {
                fprintf(stderr, "virtual_board: disconnect %u after %u blocks\n",
                        disconnects_done, g_proto.blocks_sent);
            }
            pty_close(&g_pty);
            if (g_opt.link_path != NULL) {
                unlink(g_opt.link_path);
            }
            sleep_s(g_opt.reconnect_delay_ms / 1000.0);
            if (pty_open(&g_pty) != 0) {
                die("pty");
            }
            lhb_cobs_dec_init(&g_proto.dec, g_proto.rx_raw, sizeof g_proto.rx_raw);
            blocks_at_connect = g_proto.blocks_sent;
        }
    }
    pty_close(&g_pty);
    if (g_opt.link_path != NULL) {
        unlink(g_opt.link_path);
    }
    if (g_opt.verbose) {
        fprintf(stderr, "virtual_board: stopped (%u good frames, %u bad, %u blocks, %llu bytes)\n",
                g_proto.frames_ok, g_proto.frames_bad, g_proto.blocks_sent,
                (unsigned long long)g_tx_bytes);
    }
    return 0;
}
