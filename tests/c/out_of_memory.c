/* An allocation that fails past the memory estimate is an error status, not an abort (issue 23,
 * item 1). Two facing plates of K x K quads (one emits) at basis order 0 without visibility: the
 * link rows hold ~K^4 pairs, the link store they go into as much again. The budget is set huge so
 * that the estimate lets the bake start; then the address space is limited (RLIMIT_AS) to what the
 * process has now plus ROOM_MB, which holds the rows but not the store: building the store fails,
 * and gr_session_solve_frame must return GR_STATUS_OUT_OF_MEMORY with a one-line message, leaving
 * the session as it was (no frame to read; freed without trouble). `out_of_memory measure` runs without the limit and
 * prints the address space the bake peaked at (to size ROOM_MB).
 * Built and run by tests/c_abi.rs (Linux): cc -Wall -Wextra -Werror -std=c11. Exit 0 = passed. */

#define _GNU_SOURCE
#include "galerkin_radiosity.h"

#include <malloc.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>

#define K 45
#define ROOM_MB 200

/* VmSize or VmPeak of this process, in kB (0 when unknown). */
static long vm_kb(const char *field) {
    FILE *f = fopen("/proc/self/status", "r");
    char line[256];
    long kb = 0;
    if (f == NULL) {
        return 0;
    }
    while (fgets(line, sizeof line, f) != NULL) {
        if (strncmp(line, field, strlen(field)) == 0) {
            kb = atol(line + strlen(field) + 1);
        }
    }
    fclose(f);
    return kb;
}

int main(int argc, char **argv) {
    int measure = argc > 1 && strcmp(argv[1], "measure") == 0;
    /* One malloc arena: a worker thread's own arena would reserve 64 MB of address space. */
    mallopt(M_ARENA_MAX, 1);

    static float vertices[2 * (K + 1) * (K + 1) * 3];
    static uint32_t face_indices[2 * K * K * 4];
    static uint32_t face_vertex_counts[2 * K * K];
    static uint32_t face_materials[2 * K * K];
    const uint32_t vertex_counts[2] = {(K + 1) * (K + 1), (K + 1) * (K + 1)};
    const uint32_t face_counts[2] = {K * K, K * K};
    const float reflectance[6] = {0.5f, 0.5f, 0.5f, 0.0f, 0.0f, 0.0f};
    const float emission[6] = {0.0f, 0.0f, 0.0f, 1.0f, 1.0f, 1.0f};
    for (int p = 0; p < 2; p++) {
        for (int j = 0; j <= K; j++) {
            for (int i = 0; i <= K; i++) {
                float *v = &vertices[3 * (p * (K + 1) * (K + 1) + j * (K + 1) + i)];
                v[0] = (float)i / K;
                v[1] = (float)j / K;
                v[2] = (float)p; /* plate 0 at z = 0 facing up, plate 1 at z = 1 facing down */
            }
        }
        for (int j = 0; j < K; j++) {
            for (int i = 0; i < K; i++) {
                int f = p * K * K + j * K + i;
                uint32_t a = j * (K + 1) + i, b = a + 1, c = a + K + 2, d = a + K + 1;
                uint32_t *q = &face_indices[4 * f];
                if (p == 0) {
                    q[0] = a, q[1] = b, q[2] = c, q[3] = d;
                } else {
                    q[0] = a, q[1] = d, q[2] = c, q[3] = b;
                }
                face_vertex_counts[f] = 4;
                face_materials[f] = (uint32_t)p;
            }
        }
    }

    GrSettings settings;
    if (gr_settings_default(&settings) != GR_STATUS_OK) {
        return 1;
    }
    settings.basis_order = 0;
    settings.quadrature_order = 2;
    settings.visibility = 0;
    settings.corner_gather = 0;
    settings.threads = 1;
    settings.memory_budget_mb = (uint64_t)1 << 40; /* the estimate must not refuse it */
    GrSession *s = NULL;
    GrStatus st = gr_session_new(&settings, 2, reflectance, emission, 2, vertex_counts, vertices,
                                 face_counts, face_vertex_counts, face_indices, face_materials,
                                 NULL, sizeof vertices / sizeof vertices[0],
                                 sizeof face_indices / sizeof face_indices[0], &s);
    if (st != GR_STATUS_OK) {
        char buf[512];
        gr_last_error(buf, sizeof buf);
        fprintf(stderr, "gr_session_new: %d %s\n", (int)st, buf);
        return 1;
    }
    long before = vm_kb("VmSize:");
    if (!measure) {
        struct rlimit limit;
        if (before == 0 || getrlimit(RLIMIT_AS, &limit) != 0) {
            fprintf(stderr, "cannot read the address space limit\n");
            return 1;
        }
        limit.rlim_cur = (rlim_t)(before + ROOM_MB * 1024L) * 1024;
        if (setrlimit(RLIMIT_AS, &limit) != 0) {
            fprintf(stderr, "cannot limit the address space\n");
            return 1;
        }
    }
    st = gr_session_solve_frame(s, 1.0, NULL, NULL);
    char message[512];
    size_t len = gr_last_error(message, sizeof message);
    printf("address space before %ld MB, peak %ld MB; status %d: %s\n", before / 1024,
           vm_kb("VmPeak:") / 1024, (int)st, message);
    /* The session is as it was: no frame to read, and it frees cleanly. */
    static float rgb[3 * K * K];
    GrStatus read = gr_session_face_radiosity(s, 0, rgb, 3 * K * K);
    gr_session_free(s);
    if (measure) {
        return st == GR_STATUS_OK ? 0 : 1;
    }
    if (st != GR_STATUS_OUT_OF_MEMORY) {
        fprintf(stderr, "expected GR_STATUS_OUT_OF_MEMORY (%d)\n", (int)GR_STATUS_OUT_OF_MEMORY);
        return 1;
    }
    if (read != GR_STATUS_NOT_SOLVED) {
        fprintf(stderr, "reading after the failure gave %d, not GR_STATUS_NOT_SOLVED\n", (int)read);
        return 1;
    }
    if (strncmp(message, "out of memory while building ", 29) != 0 || strchr(message, '\n') != NULL ||
        len >= sizeof message) {
        fprintf(stderr, "not the one-line out-of-memory message\n");
        return 1;
    }
    printf("all checks passed\n");
    return 0;
}
