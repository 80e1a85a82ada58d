/* The work of bench_latency and bench_throughput done with Cyclone DDS's C API, from the same
 * IDL (BenchPayload.idl through idlc), so that cpm can be set beside Cyclone doing the same
 * work and not only beside ddsperf (which always batches its writes).
 *
 *   cyclone_bench pong   [--domain D]                      echoes bench_ping on bench_pong until SIGTERM
 *   cyclone_bench ping   [--domain D] [--size B] [--count N] [--warmup W] [--blocks]
 *                        prints one one-way latency (round trip / 2) in µs per line, after W warm-up;
 *                        --blocks: stays warm, one block per line "COUNT WARMUP" of stdin, each ended by "done"
 *   cyclone_bench sub    [--domain D] [--listener]         counts until the end marker, then prints
 *                        "received N lost L rate R complete 1" (samples/s between first and last
 *                        arrival); --listener takes samples in Cyclone's receive thread
 *   cyclone_bench pub    [--domain D] [--size B] [--seconds S] [--batch]
 *                        writes as fast as the writer accepts for S seconds, then the end marker;
 *                        --batch packs writes into fewer messages (dds_write_set_batch), as ddsperf does
 *
 * --touch: every sample taken has all its bytes read (a checksum), on whichever side takes it.
 * --type blob sends BenchBlob (BenchLarge.idl, up to 1 MiB) instead of BenchPayload (up to 70,000 B):
 * the same layout, so the code below handles both as BenchPayload.
 * --type frame sends the plain BenchFrame307k or BenchFrame1M (--size 307200 or 1048576; ping and
 * pong only): fixed-size, the types Cyclone carries through iceoryx shared memory.
 * --loan (with --type frame): every sample written is loaned from Cyclone (dds_loan_sample), a
 * chunk in iceoryx's shared memory, and only its sequence number written, as cpm's write_in_place
 * does; refused unless iox-roudi runs and CYCLONEDDS_URI enables SharedMemory.
 *
 * QoS as in the cpm benchmarks: reliable; keep-last 1 for ping-pong, keep-all for throughput.
 * Transports come from CYCLONEDDS_URI (the benchmarks pin Cyclone to loopback UDP). */
#include "BenchLarge.h"
#include "BenchPayload.h"

#include <stddef.h>

#include <dds/dds.h>
#include <dds/ddsc/dds_loan_api.h>

#include <signal.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define END_MARKER UINT64_MAX

static volatile sig_atomic_t g_stop = 0;
/* --touch: every sample taken has each of its bytes read (a checksum), as a reader that uses
 * what it receives does; bench_large asks for it on both sides of every case. */
static int g_touch = 0;
static volatile uint64_t g_checksum = 0;
/* --type frame: the plain type's size (its data follows a 32-bit sequence number); 0 otherwise. */
static size_t g_frame = 0;
static int g_loan = 0;

static void touch(const void* sample)
{
    if (!g_touch) return;
    uint64_t sum = 0;
    if (g_frame) {
        const unsigned char* data = (const unsigned char*)sample + sizeof(uint32_t);
        for (size_t i = 0; i < g_frame - sizeof(uint32_t); ++i) sum += data[i];
    } else {
        const BenchPayload* p = (const BenchPayload*)sample;
        for (uint32_t i = 0; i < p->data._length; ++i) sum += p->data._buffer[i];
    }
    g_checksum += sum;
}

/* A sample's sequence number, whatever the type (a frame's is 32 bits). */
static uint64_t seq_of(const void* sample)
{
    if (g_frame) return *(const uint32_t*)sample;
    return ((const BenchPayload*)sample)->seq;
}

static void check(dds_return_t rc, const char* what);

/* Writes a sample numbered `seq`: `own` (this side's sample) with its number set, or with
 * --loan a chunk loaned from Cyclone with only its number written. */
static void write_numbered(dds_entity_t writer, void* own, uint64_t seq, const char* what)
{
    void* sample = own;
    if (g_loan) check(dds_loan_sample(writer, &sample), "loan a sample");
    if (g_frame)
        *(uint32_t*)sample = (uint32_t)seq;
    else
        ((BenchPayload*)sample)->seq = seq;
    check(dds_write(writer, sample), what);
}
static void on_signal(int sig)
{
    (void)sig;
    g_stop = 1;
}

static int64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static void check(dds_return_t rc, const char* what)
{
    if (rc < 0) {
        fprintf(stderr, "cyclone_bench: %s: %s\n", what, dds_strretcode(rc));
        exit(1);
    }
}

static const char* arg(int argc, char** argv, const char* name, const char* fallback)
{
    for (int i = 1; i + 1 < argc; ++i)
        if (strcmp(argv[i], name) == 0) return argv[i + 1];
    return fallback;
}

static int flag(int argc, char** argv, const char* name)
{
    for (int i = 1; i < argc; ++i)
        if (strcmp(argv[i], name) == 0) return 1;
    return 0;
}

static dds_qos_t* qos_for(int keep_all)
{
    dds_qos_t* q = dds_create_qos();
    dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_SECS(10));
    if (keep_all)
        dds_qset_history(q, DDS_HISTORY_KEEP_ALL, 0);
    else
        dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 1);
    return q;
}

_Static_assert(offsetof(BenchBlob, seq) == offsetof(BenchPayload, seq) && offsetof(BenchBlob, data) == offsetof(BenchPayload, data) &&
                   sizeof(BenchBlob) == sizeof(BenchPayload),
               "BenchBlob must be laid out as BenchPayload");
static const dds_topic_descriptor_t* g_type = &BenchPayload_desc;

static dds_entity_t make_topic(dds_entity_t participant, const char* name)
{
    dds_entity_t t = dds_create_topic(participant, g_type, name, NULL, NULL);
    check(t, name);
    return t;
}

/* Waits until a writer has a matched reader, or a reader a matched writer (or the stop flag). */
static void wait_matched(dds_entity_t entity, int is_writer)
{
    for (int i = 0; i < 20000 && !g_stop; ++i) {
        uint32_t count;
        if (is_writer) {
            dds_publication_matched_status_t st;
            check(dds_get_publication_matched_status(entity, &st), "publication matched status");
            count = st.current_count;
        } else {
            dds_subscription_matched_status_t st;
            check(dds_get_subscription_matched_status(entity, &st), "subscription matched status");
            count = st.current_count;
        }
        if (count >= 1) return;
        dds_sleepfor(DDS_MSECS(1));
    }
    fprintf(stderr, "cyclone_bench: no %s matched within 20 s\n", is_writer ? "reader" : "writer");
    exit(1);
}

/* Waits for data on `reader` (up to timeout) and takes one sample as a loan: returns 1 with
 * *sample set, 0 on timeout. The caller returns the loan. */
static int take_one(dds_entity_t waitset, dds_entity_t reader, void** sample, dds_duration_t timeout)
{
    dds_sample_info_t info;
    for (;;) {
        sample[0] = NULL;
        const dds_return_t n = dds_take(reader, sample, &info, 1, 1);
        check(n, "take");
        if (n == 1) {
            if (info.valid_data) {
                touch(sample[0]);
                return 1;
            }
            dds_return_loan(reader, sample, 1);
            continue;
        }
        const dds_return_t w = dds_waitset_wait(waitset, NULL, 0, timeout);
        check(w, "wait");
        if (w == 0) return 0;
    }
}

static dds_entity_t waitset_on(dds_entity_t participant, dds_entity_t reader)
{
    const dds_entity_t ws = dds_create_waitset(participant);
    const dds_entity_t cond = dds_create_readcondition(reader, DDS_ANY_STATE);
    check(ws, "waitset");
    check(cond, "read condition");
    check(dds_waitset_attach(ws, cond, reader), "attach");
    return ws;
}

static void fill(BenchPayload* msg, size_t size)
{
    memset(msg, 0, sizeof *msg);
    msg->data._buffer = dds_alloc(size ? size : 1);
    memset(msg->data._buffer, 0x5a, size);
    msg->data._length = (uint32_t)size;
    msg->data._maximum = (uint32_t)size;
    msg->data._release = true;
}

/* A ping-pong side: a reader of one topic with its wait set, a writer of the other (keep-last 1). */
struct side
{
    dds_entity_t reader, writer, waitset;
};

static struct side open_side(dds_entity_t participant, const char* read_topic, const char* write_topic)
{
    struct side s;
    dds_qos_t* q = qos_for(0);
    s.reader = dds_create_reader(participant, make_topic(participant, read_topic), q, NULL);
    s.writer = dds_create_writer(participant, make_topic(participant, write_topic), q, NULL);
    check(s.reader, read_topic);
    check(s.writer, write_topic);
    dds_delete_qos(q);
    s.waitset = waitset_on(participant, s.reader);
    return s;
}

/* --loan needs Cyclone's shared memory under the writer; says what is missing otherwise. */
static void require_loans(dds_entity_t writer)
{
    if (!g_loan || dds_is_loan_available(writer)) return;
    fprintf(stderr, "cyclone_bench: --loan: no loans on this writer: Cyclone's shared memory needs iox-roudi running, "
                    "SharedMemory enabled in CYCLONEDDS_URI and a fixed-size type (--type frame)\n");
    exit(1);
}

static int pong(dds_entity_t participant)
{
    const struct side s = open_side(participant, "bench_ping", "bench_pong");
    require_loans(s.writer);
    void* sample[1];
    while (!g_stop) {
        if (!take_one(s.waitset, s.reader, sample, DDS_MSECS(100))) continue;
        if (g_loan)
            write_numbered(s.writer, NULL, seq_of(sample[0]), "write pong");
        else
            check(dds_write(s.writer, sample[0]), "write pong");
        dds_return_loan(s.reader, sample, 1);
    }
    return 0;
}

/* `warmup` + `count` round trips on a matched side, numbered from *seq on; prints each counted
 * one-way time (µs) on a line of its own. */
static int ping_block(const struct side* s, void* msg, uint64_t* seq, long count, long warmup)
{
    void* sample[1];
    for (long i = 0; i < warmup + count && !g_stop; ++i, ++*seq) {
        const int64_t t0 = now_ns();
        write_numbered(s->writer, msg, *seq, "write ping");
        if (!take_one(s->waitset, s->reader, sample, DDS_SECS(5))) {
            fprintf(stderr, "cyclone_bench: no pong for ping %llu within 5 s\n", (unsigned long long)*seq);
            return 1;
        }
        const int64_t t1 = now_ns();
        const uint64_t got = seq_of(sample[0]);
        dds_return_loan(s->reader, sample, 1);
        if (got != *seq) {
            fprintf(stderr, "cyclone_bench: pong %llu for ping %llu\n", (unsigned long long)got, (unsigned long long)*seq);
            return 1;
        }
        if (i >= warmup) printf("%.3f\n", (double)(t1 - t0) / 2000.0);
    }
    return 0;
}

/* Pings until one comes back (200 ms each, up to 20 s): iceoryx joins a publisher to a
 * subscriber through RouDi after DDS matched them, and a ping sent before is lost. Later
 * echoes of the lost pings are drained, so the blocks start clean. */
static int handshake(const struct side* s, void* msg, uint64_t* seq)
{
    void* sample[1];
    for (int attempt = 0; attempt < 100 && !g_stop; ++attempt, ++*seq) {
        write_numbered(s->writer, msg, *seq, "write ping");
        while (take_one(s->waitset, s->reader, sample, DDS_MSECS(200))) {
            const uint64_t got = seq_of(sample[0]);
            dds_return_loan(s->reader, sample, 1);
            if (got != *seq) continue;
            ++*seq;
            while (take_one(s->waitset, s->reader, sample, DDS_MSECS(50))) dds_return_loan(s->reader, sample, 1);
            return 0;
        }
    }
    fprintf(stderr, "cyclone_bench: no pong to any of 100 pings in 20 s\n");
    return 1;
}

/* One block, or with `blocks` one block per line of stdin ("COUNT WARMUP"), each ended by a
 * line "done", the process staying warm in between (as the cpm side's pingers do), until stdin ends. */
static int ping(dds_entity_t participant, size_t size, long count, long warmup, int blocks)
{
    const struct side s = open_side(participant, "bench_pong", "bench_ping");
    require_loans(s.writer);
    wait_matched(s.writer, 1);
    wait_matched(s.reader, 0); /* the pong's writer must see this reader before the first ping counts */
    BenchPayload msg;
    void* own = &msg;
    if (g_frame) {
        own = dds_alloc(g_frame);
        memset(own, 0x5a, g_frame);
    } else {
        fill(&msg, size);
    }
    uint64_t seq = 0;
    int rc = handshake(&s, own, &seq);
    if (rc != 0) {
    } else if (!blocks) {
        rc = ping_block(&s, own, &seq, count, warmup);
    } else {
        char line[64];
        while (rc == 0 && fgets(line, sizeof line, stdin)) {
            if (sscanf(line, "%ld %ld", &count, &warmup) != 2) {
                fprintf(stderr, "cyclone_bench: expected 'COUNT WARMUP', got '%s'\n", line);
                rc = 1;
                break;
            }
            rc = ping_block(&s, own, &seq, count, warmup);
            printf("done\n");
            fflush(stdout);
        }
    }
    if (g_frame)
        dds_free(own);
    else
        BenchPayload_free(&msg, DDS_FREE_CONTENTS);
    return rc;
}

/* What the subscriber counts; taken from the reader on a waiting thread or in the listener. */
struct counter
{
    uint64_t received, lost, next_seq;
    int64_t first, last;
    atomic_int done;
};

static void take_all(dds_entity_t reader, struct counter* c)
{
    enum { kBatch = 256 };
    void* samples[kBatch];
    dds_sample_info_t infos[kBatch];
    for (;;) {
        samples[0] = NULL;
        const dds_return_t n = dds_take(reader, samples, infos, kBatch, kBatch);
        check(n, "take");
        if (n == 0) return;
        const int64_t t = now_ns();
        for (dds_return_t i = 0; i < n; ++i) {
            if (!infos[i].valid_data) continue;
            touch(samples[i]);
            const uint64_t seq = ((BenchPayload*)samples[i])->seq;
            if (seq == END_MARKER) {
                c->done = 1;
                continue;
            }
            if (c->received == 0) c->first = t;
            c->last = t;
            if (seq > c->next_seq) c->lost += seq - c->next_seq;
            c->next_seq = seq + 1;
            ++c->received;
        }
        dds_return_loan(reader, samples, n);
    }
}

static void on_data(dds_entity_t reader, void* arg) { take_all(reader, (struct counter*)arg); }

/* listener != 0: samples are taken in Cyclone's receive thread (as ddsperf's sub does by
 * default, and as the raw Fast DDS listener case); else on this thread from a wait set, the
 * shape of cpm's AsyncReader. */
static int sub(dds_entity_t participant, int listener)
{
    static struct counter c;
    dds_qos_t* q = qos_for(1);
    dds_listener_t* l = NULL;
    if (listener) {
        l = dds_create_listener(&c);
        dds_lset_data_available(l, on_data);
    }
    const dds_entity_t reader = dds_create_reader(participant, make_topic(participant, "bench_throughput"), q, l);
    check(reader, "reader");
    dds_delete_qos(q);
    if (l) dds_delete_listener(l);
    const dds_entity_t ws = waitset_on(participant, reader);
    const int64_t give_up = now_ns() + (int64_t)120 * 1000000000;
    while (!c.done && !g_stop && now_ns() < give_up) {
        if (listener) {
            dds_sleepfor(DDS_MSECS(10));
            continue;
        }
        take_all(reader, &c);
        if (!c.done) check(dds_waitset_wait(ws, NULL, 0, DDS_MSECS(100)), "wait");
    }
    if (listener) dds_set_listener(reader, NULL);
    const double seconds = (double)(c.last - c.first) / 1e9;
    printf("received %llu lost %llu rate %.0f complete %d\n", (unsigned long long)c.received, (unsigned long long)c.lost,
           seconds > 0 ? (double)c.received / seconds : 0.0, atomic_load(&c.done));
    return c.done ? 0 : 1;
}

static int pub(dds_entity_t participant, size_t size, double seconds, int batch)
{
    /* A writer takes the batching setting when it is created (ddsperf sets it first thing). */
    dds_write_set_batch(batch != 0);
    dds_qos_t* q = qos_for(1);
    const dds_entity_t writer = dds_create_writer(participant, make_topic(participant, "bench_throughput"), q, NULL);
    check(writer, "writer");
    dds_delete_qos(q);
    wait_matched(writer, 1);
    BenchPayload msg;
    fill(&msg, size);
    const int64_t end = now_ns() + (int64_t)(seconds * 1e9);
    uint64_t seq = 0;
    while (!g_stop) {
        /* The clock is read every 64 writes: a read per write would cost as much as a write. */
        if ((seq & 63) == 0 && now_ns() >= end) break;
        msg.seq = seq++;
        check(dds_write(writer, &msg), "write");
    }
    msg.seq = END_MARKER;
    check(dds_write(writer, &msg), "write end marker");
    if (batch) dds_write_flush(writer);
    /* Every sample acknowledged before the writer goes (keep-all, reliable). */
    check(dds_wait_for_acks(writer, DDS_SECS(30)), "wait for acknowledgements");
    printf("written %llu\n", (unsigned long long)seq);
    BenchPayload_free(&msg, DDS_FREE_CONTENTS);
    return 0;
}

int main(int argc, char** argv)
{
    if (argc < 2 || flag(argc, argv, "--help")) {
        fputs("usage: cyclone_bench pong|ping|sub|pub [--domain D] [--size B] [--count N] [--warmup W]"
              " [--seconds S] [--batch] [--listener] [--type payload|blob|frame] [--touch] [--loan]\n",
              argc < 2 ? stderr : stdout);
        return argc < 2 ? 2 : 0;
    }
    const char* role = argv[1];
    g_touch = flag(argc, argv, "--touch");
    const int domain = atoi(arg(argc, argv, "--domain", "0"));
    const char* type = arg(argc, argv, "--type", "payload");
    size_t bound = 70000;
    const size_t size = (size_t)atol(arg(argc, argv, "--size", "100"));
    g_loan = flag(argc, argv, "--loan");
    if (strcmp(type, "blob") == 0) {
        g_type = &BenchBlob_desc;
        bound = 1048576;
    } else if (strcmp(type, "frame") == 0) {
        if (size != sizeof(BenchFrame307k) && size != sizeof(BenchFrame1M)) {
            fprintf(stderr, "cyclone_bench: --type frame: --size %zu is neither %zu nor %zu (BenchFrame307k, BenchFrame1M)\n", size,
                    sizeof(BenchFrame307k), sizeof(BenchFrame1M));
            return 2;
        }
        if (strcmp(role, "ping") != 0 && strcmp(role, "pong") != 0) {
            fprintf(stderr, "cyclone_bench: --type frame is for ping and pong only\n");
            return 2;
        }
        g_frame = size;
        g_type = size == sizeof(BenchFrame1M) ? &BenchFrame1M_desc : &BenchFrame307k_desc;
        bound = size;
    } else if (strcmp(type, "payload") != 0) {
        fprintf(stderr, "cyclone_bench: --type %s: expected payload, blob or frame\n", type);
        return 2;
    }
    if (g_loan && !g_frame) {
        fprintf(stderr, "cyclone_bench: --loan needs --type frame (Cyclone loans fixed-size samples only)\n");
        return 2;
    }
    if (size > bound) {
        fprintf(stderr, "cyclone_bench: --size %zu is larger than the type's bound (%zu; --type blob takes up to 1048576)\n", size, bound);
        return 2;
    }
    signal(SIGTERM, on_signal);
    signal(SIGINT, on_signal);
    const dds_entity_t participant = dds_create_participant((dds_domainid_t)domain, NULL, NULL);
    check(participant, "participant");
    int rc = 2;
    if (strcmp(role, "pong") == 0)
        rc = pong(participant);
    else if (strcmp(role, "ping") == 0)
        rc = ping(participant, size, atol(arg(argc, argv, "--count", "10000")), atol(arg(argc, argv, "--warmup", "1000")), flag(argc, argv, "--blocks"));
    else if (strcmp(role, "sub") == 0)
        rc = sub(participant, flag(argc, argv, "--listener"));
    else if (strcmp(role, "pub") == 0)
        rc = pub(participant, size, atof(arg(argc, argv, "--seconds", "5")), flag(argc, argv, "--batch"));
    else
        fprintf(stderr, "cyclone_bench: unknown role '%s' (pong, ping, sub or pub)\n", role);
    fflush(stdout);
    dds_delete(participant);
    return rc;
}
