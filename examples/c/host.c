/*
 * A C host embedding fdd through its C ABI (monitor/include/fdd.h): the loop a vehicle
 * monitoring task runs, fed here from a CSV file of samples instead of a bus.
 *
 *   fdd replay fixtures/data/throttle_tps_open.mcap --samples samples.csv
 *   make -C examples/c && examples/c/build/host samples.csv throttle
 *
 * Arguments: the samples file (`t_ns,signal,value` rows, as `fdd replay --samples` writes
 * them) and the monitors the vehicle has (default "throttle"; comma-separated), so that the
 * "no signal" monitor watches only their signals.
 *
 * It builds the runtime from the embedded default configuration, resolves each signal name
 * once, and per frame (the samples of one time stamp) advances the runtime's time to just
 * before the frame, pushes the frame's samples in one batch and drains the events. At the
 * end it prints the throttle position and its source, reads the DTC memory by status mask
 * (UDS 0x19 0x02) with freeze frames and extended data, ends the operation cycle, clears the
 * DTCs (UDS 0x14) and checks that none is left failed.
 *
 * Output lines starting with "EVENT" are every DTC status change up to the end of the
 * operation cycle: t_ns, time_s, DTC, status before and after, event name; tests compare
 * them with `fdd replay --events`.
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fdd.h"

#define MAX_SIGNALS 64
#define MAX_FRAME 64
#define EVENT_BUF 64

/* A failed call: print its status and fdd's message, and leave. */
#define CHECK(call)                                                                          \
    do {                                                                                     \
        fdd_status s_ = (call);                                                              \
        if (s_ != FDD_OK) {                                                                  \
            char msg_[512];                                                                  \
            fdd_last_error(msg_, sizeof msg_);                                               \
            fprintf(stderr, "%s:%d: %s: %s: %s\n", __FILE__, __LINE__, #call,                \
                    fdd_status_name(s_), msg_);                                              \
            goto fail;                                                                       \
        }                                                                                    \
    } while (0)

struct signal_name {
    char name[64];
    uint32_t id;
};

/* Prints and counts the waiting events; `tag` marks those after the cycle's end. */
static int drain(fdd_runtime *rt, const char *tag) {
    fdd_event ev[EVENT_BUF];
    size_t n = 0;
    do {
        CHECK(fdd_events_drain(rt, ev, EVENT_BUF, &n));
        for (size_t i = 0; i < n; i++) {
            char name[128];
            size_t len = 0;
            CHECK(fdd_event_name(rt, ev[i].dtc, name, sizeof name, &len));
            printf("%s %" PRIu64 " %.17g %s 0x%02X 0x%02X %s\n", tag, ev[i].t_ns, ev[i].time_s,
                   ev[i].dtc_text, ev[i].status_before, ev[i].status_after, name);
            /* A new qualified failure: its JSON form too. */
            if (!(ev[i].status_before & 0x01) && (ev[i].status_after & 0x01)) {
                char json[1024];
                CHECK(fdd_event_json(rt, &ev[i], json, sizeof json, &len));
                printf("  json %s\n", json);
            }
        }
    } while (n == EVENT_BUF);
    return 0;
fail:
    return -1;
}

/* The id of signal `name`, resolved once and kept in `table`. */
static int signal_id(fdd_runtime *rt, struct signal_name *table, size_t *count,
                     const char *name, uint32_t *id) {
    for (size_t i = 0; i < *count; i++) {
        if (strcmp(table[i].name, name) == 0) {
            *id = table[i].id;
            return 0;
        }
    }
    if (*count == MAX_SIGNALS) {
        fprintf(stderr, "more than %d signals\n", MAX_SIGNALS);
        return -1;
    }
    CHECK(fdd_signal(rt, name, id));
    snprintf(table[*count].name, sizeof table[*count].name, "%s", name);
    table[*count].id = *id;
    (*count)++;
    return 0;
fail:
    return -1;
}

/* Runs the steps due before the frame at `t_ns` (the first frame starts the operation
 * cycle), then pushes the frame's samples. */
static int feed_frame(fdd_runtime *rt, int first, uint64_t t_ns, const fdd_sample *frame,
                      size_t n) {
    size_t accepted = 0;
    if (first) {
        CHECK(fdd_start_operation_cycle(rt, t_ns)); /* ignition on */
    } else {
        CHECK(fdd_advance_to(rt, t_ns - 1, NULL));
    }
    if (drain(rt, "EVENT") != 0) {
        goto fail;
    }
    CHECK(fdd_push_batch(rt, frame, n, &accepted));
    return 0;
fail:
    return -1;
}

static void print_dtc_memory(fdd_runtime *rt, uint8_t mask) {
    fdd_dtc_record dtcs[64];
    size_t count = 0;
    if (fdd_dtcs_by_status_mask(rt, mask, dtcs, 64, &count) != FDD_OK) {
        return;
    }
    printf("DTCs by status mask 0x%02X: %zu\n", mask, count);
    for (size_t i = 0; i < count && i < 64; i++) {
        fdd_extended_data ext;
        fdd_freeze_frame ff;
        fdd_freeze_value values[16];
        printf("  %s  0x%02X", dtcs[i].dtc_text, dtcs[i].status);
        if (fdd_dtc_extended_data(rt, dtcs[i].dtc, &ext) == FDD_OK) {
            printf("  occurrences %u  max FDC %d", ext.occurrence_counter, ext.max_fdc);
        }
        printf("\n");
        if (fdd_dtc_freeze_frame(rt, dtcs[i].dtc, &ff, values, 16) == FDD_OK) {
            printf("    freeze frame at %.3f s:", ff.stored_time_s);
            for (size_t k = 0; k < ff.value_count && k < 16; k++) {
                printf(" %s=%.4f", values[k].name, values[k].value);
            }
            printf("\n");
        }
    }
}

int main(int argc, char **argv) {
    const char *path = argc > 1 ? argv[1] : "samples.csv";
    const char *monitors = argc > 2 ? argv[2] : "throttle";
    fdd_builder *builder = NULL;
    fdd_runtime *rt = NULL;
    FILE *f = NULL;
    struct signal_name names[MAX_SIGNALS];
    size_t n_names = 0;
    fdd_sample frame[MAX_FRAME];
    size_t n_frame = 0;
    uint64_t frame_t = 0, last_t = 0;
    int first = 1, ok = 0;
    char line[256];
    fdd_estimate pos;
    size_t cleared = 0, left = 0;

    printf("fdd %s\n", fdd_version());
    CHECK(fdd_builder_new(NULL, 0, &builder)); /* the embedded default configuration */
    CHECK(fdd_builder_only_monitors(builder, monitors));
    CHECK(fdd_builder_event_capacity(builder, 1024));
    CHECK(fdd_runtime_build(builder, &rt));
    fdd_builder_free(builder);
    builder = NULL;

    f = fopen(path, "r");
    if (f == NULL) {
        perror(path);
        goto fail;
    }
    if (fgets(line, sizeof line, f) == NULL || strncmp(line, "t_ns,signal,value", 17) != 0) {
        fprintf(stderr, "%s: line 1: expected the header t_ns,signal,value\n", path);
        goto fail;
    }
    for (unsigned long lineno = 2; fgets(line, sizeof line, f) != NULL; lineno++) {
        char name[64];
        uint64_t t;
        double v;
        uint32_t id;
        if (sscanf(line, "%" SCNu64 ",%63[^,],%lf", &t, name, &v) != 3) {
            fprintf(stderr, "%s: line %lu: expected t_ns,signal,value\n", path, lineno);
            goto fail;
        }
        if (signal_id(rt, names, &n_names, name, &id) != 0) {
            goto fail;
        }
        if (n_frame > 0 && t != frame_t) {
            if (feed_frame(rt, first, frame_t, frame, n_frame) != 0) {
                goto fail;
            }
            first = 0;
            n_frame = 0;
        }
        if (n_frame == MAX_FRAME) {
            fprintf(stderr, "%s: line %lu: more than %d samples at one time\n", path, lineno,
                    MAX_FRAME);
            goto fail;
        }
        frame_t = t;
        frame[n_frame].signal = id;
        frame[n_frame].t_ns = t;
        frame[n_frame].value = v;
        n_frame++;
        last_t = t;
    }
    if (n_frame > 0 && feed_frame(rt, first, frame_t, frame, n_frame) != 0) {
        goto fail;
    }
    fclose(f);
    f = NULL;
    CHECK(fdd_advance_to(rt, last_t, NULL));
    if (drain(rt, "EVENT") != 0) {
        goto fail;
    }

    if (fdd_latest_estimate(rt, "throttle_angle", &pos) == FDD_OK) {
        printf("throttle position %.1f deg [%.1f, %.1f] from %s\n", pos.value, pos.lower,
               pos.upper, pos.source);
    }
    /* The workshop tester: testFailedThisOperationCycle or pendingDTC. */
    print_dtc_memory(rt, 0x06);

    CHECK(fdd_end_operation_cycle(rt, last_t + 1)); /* ignition off */
    if (drain(rt, "EVENT") != 0) {
        goto fail;
    }
    CHECK(fdd_clear_dtc(rt, 0xFFFFFF, last_t + 1, &cleared));
    if (drain(rt, "CLEARED") != 0) {
        goto fail;
    }
    printf("cleared %zu DTCs\n", cleared);
    CHECK(fdd_start_operation_cycle(rt, last_t + 2)); /* the next drive */
    CHECK(fdd_dtcs_by_status_mask(rt, 0x2F, NULL, 0, &left));
    printf("DTCs with any failure bit after the clear: %zu\n", left);
    ok = 1;

fail:
    if (f != NULL) {
        fclose(f);
    }
    fdd_builder_free(builder);
    fdd_runtime_free(rt);
    return ok ? 0 : 1;
}
