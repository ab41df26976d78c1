/* Two patches through the C ABI: a 1 x 1 emitter at z = 1 facing down (exitance 1 W/m^2, black)
 * over a 1 x 1 receiver at z = 0 facing up (reflectance 0.5). The receiver's area-mean radiosity
 * is rho F = 0.5 x 0.199825 (Howell C-11, parallel opposed unit squares at unit distance); the
 * emitter is black so that no second bounce adds to it. Also checks error paths and NULLs.
 * Built and run by tests/c_abi.rs: cc -Wall -Wextra -Werror -std=c11. Exit 0 = all passed. */

#include "galerkin_radiosity.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int failures = 0;

#define CHECK(cond)                                                              \
    do {                                                                         \
        if (!(cond)) {                                                           \
            fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #cond); \
            failures++;                                                          \
        }                                                                        \
    } while (0)

static const char *last_error(void) {
    static char buf[1024];
    gr_last_error(buf, sizeof buf);
    return buf;
}

typedef struct Counter {
    int calls;
    double last_fraction;
} Counter;

static int32_t on_progress(double fraction, const char *stage, void *user) {
    Counter *c = (Counter *)user;
    c->calls++;
    c->last_fraction = fraction;
    return stage != NULL && fraction >= 0.0 && fraction <= 1.0;
}

/* Object 0: the receiver, identity placement. Object 1: the emitter, modelled at z = 0 facing
 * down and placed at z = 1 by its (row-major) matrix. */
static const float reflectance[6] = {0.5f, 0.5f, 0.5f, 0.0f, 0.0f, 0.0f};
static const float emission[6] = {0.0f, 0.0f, 0.0f, 1.0f, 1.0f, 1.0f};
static const uint32_t vertex_counts[2] = {4, 4};
static const float vertices[24] = {
    0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, /* receiver, counter-clockwise from +z */
    0, 0, 0, 0, 1, 0, 1, 1, 0, 1, 0, 0, /* emitter, counter-clockwise from -z */
};
static const uint32_t face_counts[2] = {1, 1};
static const uint32_t face_vertex_counts[2] = {4, 4};
static const uint32_t face_materials[2] = {0, 1};
static const float matrices[32] = {
    1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1,
    1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 1, 0, 0, 0, 1,
};

static GrStatus make(const GrSettings *settings, const uint32_t *face_indices, size_t vertices_len,
                     GrSession **out) {
    return gr_session_new(settings, 2, reflectance, emission, 2, vertex_counts, vertices,
                          face_counts, face_vertex_counts, face_indices, face_materials, matrices,
                          vertices_len, 8, out);
}

int main(void) {
    static const uint32_t face_indices[8] = {0, 1, 2, 3, 0, 1, 2, 3};
    static const uint32_t bad_indices[8] = {0, 1, 2, 3, 0, 1, 7, 3};
    const double expected = 0.5 * 0.199825;

    CHECK(gr_abi_version() == 3);
    CHECK(GR_ABI_VERSION == 3);
    CHECK(gr_version_string() != NULL && strlen(gr_version_string()) > 0);

    GrSettings settings;
    CHECK(gr_settings_default(&settings) == GR_STATUS_OK);
    CHECK(settings.method == GR_METHOD_INCREMENTAL);
    CHECK(settings.basis_order == 2);
    CHECK(gr_last_error(NULL, 0) == 0);

    /* The solve. */
    GrSession *s = NULL;
    CHECK(make(&settings, face_indices, 24, &s) == GR_STATUS_OK);
    CHECK(s != NULL);
    if (s == NULL) {
        fprintf(stderr, "gr_session_new: %s\n", last_error());
        return 1;
    }
    uint32_t n = 0;
    CHECK(gr_session_object_count(s, &n) == GR_STATUS_OK && n == 2);
    CHECK(gr_session_face_count(s, 0, &n) == GR_STATUS_OK && n == 1);
    CHECK(gr_session_corner_count(s, 1, &n) == GR_STATUS_OK && n == 4);
    float rgb[3] = {-1.0f, -1.0f, -1.0f};
    CHECK(gr_session_face_radiosity(s, 0, rgb, 3) == GR_STATUS_NOT_SOLVED);
    CHECK(rgb[0] == -1.0f);

    Counter counter = {0, -1.0};
    GrStatus st = gr_session_solve_frame(s, 1.0, on_progress, &counter);
    CHECK(st == GR_STATUS_OK);
    if (st != GR_STATUS_OK) {
        fprintf(stderr, "gr_session_solve_frame: %s\n", last_error());
    }
    CHECK(counter.calls > 0);

    CHECK(gr_session_face_radiosity(s, 0, rgb, 3) == GR_STATUS_OK);
    for (int c = 0; c < 3; c++) {
        double rel = fabs(rgb[c] - expected) / expected;
        printf("receiver B[%d] = %.6f, expected %.6f, relative error %.2e\n", c, rgb[c], expected,
               rel);
        CHECK(rel < 0.01);
    }
    float emitter[3];
    CHECK(gr_session_face_radiosity(s, 1, emitter, 3) == GR_STATUS_OK);
    CHECK(fabs(emitter[0] - 1.0) < 1e-5);

    float corners[12];
    CHECK(gr_session_corner_radiosity(s, 0, corners, 12) == GR_STATUS_OK);
    const uint32_t objects[1] = {0}, faces[1] = {0};
    const float centre_st[2] = {0.5f, 0.5f};
    float centre[3];
    CHECK(gr_session_eval(s, 1, objects, faces, centre_st, centre) == GR_STATUS_OK);
    for (int k = 0; k < 4; k++) {
        /* Corners see the emitter less than the mean does, the centre more. */
        CHECK(corners[3 * k] > 0.0f && corners[3 * k] < rgb[0]);
    }
    CHECK(centre[0] > rgb[0]);

    size_t needed = 0;
    CHECK(gr_session_frame_stats_json(s, NULL, 0, &needed) == GR_STATUS_INVALID_ARGUMENT);
    CHECK(needed > 1);
    char *json = malloc(needed);
    size_t written = 0;
    CHECK(json != NULL);
    if (json != NULL) {
        CHECK(gr_session_frame_stats_json(s, json, needed, &written) == GR_STATUS_OK);
        CHECK(written == needed && strlen(json) + 1 == needed);
        CHECK(strstr(json, "\"elements\":2") != NULL);
        printf("stats: %s\n", json);
        free(json);
    }

    /* Argument errors leave the outputs alone and explain themselves. */
    CHECK(gr_session_face_radiosity(s, 0, rgb, 2) == GR_STATUS_INVALID_ARGUMENT);
    CHECK(gr_session_face_radiosity(s, 2, rgb, 3) == GR_STATUS_INVALID_ARGUMENT);
    CHECK(strstr(last_error(), "object 2") != NULL);
    const float far_st[2] = {0.5f, 1.5f};
    centre[0] = -1.0f;
    CHECK(gr_session_eval(s, 1, objects, faces, far_st, centre) == GR_STATUS_INVALID_ARGUMENT);
    CHECK(centre[0] == -1.0f);
    const float nan_matrix[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, NAN, 0, 0, 0, 1};
    CHECK(gr_session_set_object_matrix(s, 1, nan_matrix) == GR_STATUS_INVALID_ARGUMENT);
    CHECK(gr_session_set_object_matrix(s, 1, NULL) == GR_STATUS_NULL_POINTER);
    const float red[3] = {2.0f, 0.0f, 0.0f};
    CHECK(gr_session_set_material_emission(s, 1, red) == GR_STATUS_OK);
    CHECK(gr_last_error(NULL, 0) == 0);
    CHECK(gr_session_set_material_emission(s, 5, red) == GR_STATUS_INVALID_ARGUMENT);

    /* Frame 2 with the emitter red at 2 W/m^2: B scales. */
    CHECK(gr_session_solve_frame(s, 2.0, NULL, NULL) == GR_STATUS_OK);
    CHECK(gr_session_face_radiosity(s, 0, rgb, 3) == GR_STATUS_OK);
    CHECK(fabs(rgb[0] - 2.0 * expected) / expected < 0.02 && rgb[1] == 0.0f);
    CHECK(gr_session_cancel(s) == GR_STATUS_OK);
    gr_session_free(s);

    GrSession *bad_session = NULL;
    /* The same scene through the scene builder (ABI version 2): the same frame-1 value. */
    GrSceneBuilder *builder = NULL;
    CHECK(gr_scene_builder_new(&builder) == GR_STATUS_OK && builder != NULL);
    CHECK(gr_scene_builder_set_settings(builder, &settings) == GR_STATUS_OK);
    uint32_t index = 99;
    CHECK(gr_scene_builder_add_material(builder, reflectance, emission, &index) == GR_STATUS_OK);
    CHECK(index == 0);
    CHECK(gr_scene_builder_add_material(builder, reflectance + 3, emission + 3, &index) == GR_STATUS_OK);
    CHECK(index == 1);
    for (int o = 0; o < 2; o++) {
        GrMesh mesh;
        CHECK(gr_mesh_default(&mesh) == GR_STATUS_OK);
        CHECK(mesh.struct_size == sizeof(GrMesh));
        mesh.vertex_count = 4;
        mesh.vertices = vertices + 12 * o;
        mesh.face_count = 1;
        mesh.face_vertex_counts = face_vertex_counts;
        mesh.face_materials = face_materials + o;
        mesh.face_indices = face_indices;
        mesh.face_indices_len = 4;
        mesh.matrix = matrices + 16 * o;
        CHECK(gr_scene_builder_add_mesh(builder, &mesh, &index) == GR_STATUS_OK);
        CHECK(index == (uint32_t)o);
    }
    GrSession *built = NULL;
    CHECK(gr_scene_builder_build(builder, &built) == GR_STATUS_OK && built != NULL);
    gr_scene_builder_free(builder);
    if (built != NULL) {
        float again[3];
        CHECK(gr_session_solve_frame(built, 1.0, NULL, NULL) == GR_STATUS_OK);
        CHECK(gr_session_face_radiosity(built, 0, again, 3) == GR_STATUS_OK);
        CHECK(fabs(again[0] - expected) / expected < 0.01);
        printf("builder: receiver B[0] = %.6f\n", again[0]);
        gr_session_free(built);
    }
    /* A GrSettings from a newer header (bigger) is refused with a message saying so. */
    GrSettings newer = settings;
    newer.struct_size = sizeof(GrSettings) + 8;
    CHECK(make(&newer, face_indices, 24, &bad_session) == GR_STATUS_INVALID_ARGUMENT);
    CHECK(strstr(last_error(), "newer header") != NULL);
    gr_scene_builder_free(NULL);

    /* A face index out of range: an invalid scene, the message names the face. */
    GrSession *bad = (GrSession *)&settings; /* must stay untouched */
    CHECK(make(&settings, bad_indices, 24, &bad) == GR_STATUS_INVALID_SCENE);
    CHECK(bad == (GrSession *)&settings);
    size_t len = gr_last_error(NULL, 0);
    CHECK(len > 0 && strlen(last_error()) == len);
    CHECK(strstr(last_error(), "face") != NULL);
    printf("expected error: %s\n", last_error());
    char small[8];
    CHECK(gr_last_error(small, sizeof small) == len && strlen(small) == 7);

    /* Lengths that disagree with the counts. */
    CHECK(make(&settings, face_indices, 23, &bad) == GR_STATUS_INVALID_ARGUMENT);
    CHECK(strstr(last_error(), "vertices_len") != NULL);
    GrSettings odd = settings;
    odd.method = (GrMethod)7;
    CHECK(make(&odd, face_indices, 24, &bad) == GR_STATUS_INVALID_ARGUMENT);

    /* NULLs. */
    CHECK(make(NULL, face_indices, 24, &bad) == GR_STATUS_NULL_POINTER);
    CHECK(make(&settings, NULL, 24, &bad) == GR_STATUS_NULL_POINTER);
    CHECK(make(&settings, face_indices, 24, NULL) == GR_STATUS_NULL_POINTER);
    CHECK(bad == (GrSession *)&settings);
    CHECK(gr_settings_default(NULL) == GR_STATUS_NULL_POINTER);
    CHECK(gr_session_solve_frame(NULL, 1.0, NULL, NULL) == GR_STATUS_NULL_POINTER);
    CHECK(gr_session_cancel(NULL) == GR_STATUS_NULL_POINTER);
    CHECK(gr_session_object_count(NULL, &n) == GR_STATUS_NULL_POINTER);
    CHECK(gr_session_face_radiosity(NULL, 0, rgb, 3) == GR_STATUS_NULL_POINTER);
    CHECK(gr_session_frame_stats_json(NULL, NULL, 0, &needed) == GR_STATUS_NULL_POINTER);
    CHECK(gr_session_eval(NULL, 0, NULL, NULL, NULL, NULL) == GR_STATUS_NULL_POINTER);
    CHECK(strstr(last_error(), "NULL") != NULL);
    gr_session_free(NULL);

    if (failures != 0) {
        fprintf(stderr, "%d check(s) failed\n", failures);
        return 1;
    }
    printf("two_patches: all checks passed\n");
    return 0;
}
