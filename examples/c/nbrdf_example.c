/*
 * A small C program using libnbrdf_ffi: loads a neural BRDF (*.nbrdf.json) as a material,
 * evaluates it for a few direction pairs, importance-samples light directions with a sampler of
 * the lobes stored in the file and checks their pdfs, and shows how errors are reported.
 *
 * Build (after `make install PREFIX=...` at the repository root):
 *     make -C examples/c PKG_CONFIG_PATH=PREFIX/lib/pkgconfig
 * or by hand:
 *     cc nbrdf_example.c $(pkg-config --cflags --libs nbrdf) \
 *        -Wl,-rpath,$(pkg-config --variable=libdir nbrdf) -o nbrdf_example
 * Run:
 *     ./nbrdf_example my-material.nbrdf.json
 *
 * Arrays are planar: n directions are [x0..x(n-1), y0..y(n-1), z0..z(n-1)], in the local
 * shading frame (z = normal); `view` points to the viewer, `light` to the light.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include <nbrdf.h>

#define N 4

/* Reports a failed call with the library's message; returns 1 so callers can `return fail(..)`. */
static int fail(const char *what, int32_t status) {
    fprintf(stderr, "nbrdf_example: %s failed (status %d): %s\n", what, (int)status, nbrdf_last_error());
    return 1;
}

/* Stores the unit direction with polar angle theta and azimuth phi as entry i of a planar array. */
static void set_direction(float *planar, size_t i, double theta, double phi) {
    planar[i] = (float)(sin(theta) * cos(phi));
    planar[N + i] = (float)(sin(theta) * sin(phi));
    planar[2 * N + i] = (float)cos(theta);
}

static void print_vec(const char *label, const float *planar, size_t i) {
    printf(" %s=%.9g,%.9g,%.9g", label, planar[i], planar[N + i], planar[2 * N + i]);
}

int main(int argc, char **argv) {
    if (argc != 2) {
        fprintf(stderr, "usage: %s NETWORK.nbrdf.json\n", argv[0]);
        return 2;
    }
    printf("library %s\n", nbrdf_version());

    /* One handle for networks and MERL tables alike; the info says which it is. */
    NbrdfMaterial *material = NULL;
    int32_t status = nbrdf_material_load(argv[1], &material);
    if (status != NBRDF_OK)
        return fail("nbrdf_material_load", status);

    NbrdfMaterialInfo info;
    if ((status = nbrdf_material_info(material, &info)) != NBRDF_OK)
        return fail("nbrdf_material_info", status);
    if (info.kind != NBRDF_MATERIAL_NETWORK) {
        fprintf(stderr, "nbrdf_example: %s is a MERL table, not a network\n", argv[1]);
        return 1;
    }
    const NbrdfSamplerParams *stored = &info.stored_sampling;
    const char *stored_name = NULL;
    if ((status = nbrdf_sampling_kind_name(stored->kind, &stored_name)) != NBRDF_OK)
        return fail("nbrdf_sampling_kind_name", status);
    printf("network name=%s hidden=%u parameters=%u stored_sampling=%s exponent=%.9g specular_weight=%.9g\n",
           info.name, info.hidden_width, info.parameter_count, stored_name, stored->exponent,
           stored->specular_weight);

    /* Evaluate f_r * cos(theta_light) for a few (view, light) pairs. */
    const double pi = 3.14159265358979323846;
    float view[3 * N], light[3 * N], rgb[3 * N];
    for (size_t i = 0; i < N; ++i) {
        set_direction(view, i, 0.15 + 0.3 * (double)i, 0.0);
        set_direction(light, i, 0.6 - 0.1 * (double)i, pi * (0.9 + 0.05 * (double)i));
    }
    if ((status = nbrdf_material_eval(material, view, light, N, rgb)) != NBRDF_OK)
        return fail("nbrdf_material_eval", status);
    for (size_t i = 0; i < N; ++i) {
        printf("eval");
        print_vec("view", view, i);
        print_vec("light", light, i);
        print_vec("rgb", rgb, i);
        printf("\n");
    }

    /* Importance-sample with the lobes stored in the file (a cosine lobe when it stores none). */
    NbrdfSampler *sampler = NULL;
    if ((status = nbrdf_sampler_create(material, stored, &sampler)) != NBRDF_OK)
        return fail("nbrdf_sampler_create", status);
    float u[3 * N], sampled[3 * N], weight[3 * N], pdf[N], pdf_again[N];
    for (size_t i = 0; i < N; ++i) {
        u[i] = 0.2f + 0.2f * (float)i;         /* picks the lobe of the mixture */
        u[N + i] = 0.1f + 0.25f * (float)i;
        u[2 * N + i] = 0.7f - 0.15f * (float)i;
    }
    status = nbrdf_material_sample(material, sampler, view, u, N, sampled, weight, pdf);
    if (status != NBRDF_OK)
        return fail("nbrdf_material_sample", status);
    if ((status = nbrdf_sampler_pdf(sampler, view, sampled, N, pdf_again)) != NBRDF_OK)
        return fail("nbrdf_sampler_pdf", status);
    int mismatches = 0;
    for (size_t i = 0; i < N; ++i) {
        printf("sample kind=%d exponent=%.9g specular_weight=%.9g", (int)stored->kind, stored->exponent,
               stored->specular_weight);
        print_vec("view", view, i);
        print_vec("light", sampled, i);
        print_vec("weight", weight, i);
        printf(" pdf=%.9g\n", pdf[i]);
        /* The pdf returned with a sample is the one nbrdf_sampler_pdf gives for that direction. */
        if (fabsf(pdf[i] - pdf_again[i]) > 1e-4f * fmaxf(1.0f, pdf[i]))
            mismatches++;
    }
    if (mismatches) {
        fprintf(stderr, "nbrdf_example: %d sample pdf(s) differ from nbrdf_sampler_pdf\n", mismatches);
        return 1;
    }

    /* Errors: a status code, and a message naming the function and the file. */
    NbrdfMaterial *missing = NULL;
    status = nbrdf_material_load("no-such-network.nbrdf.json", &missing);
    printf("error status=%d handle=%s\n", (int)status, missing ? "set" : "null");
    printf("message %s\n", nbrdf_last_error());
    if (status != NBRDF_ERROR_IO || missing != NULL) {
        fprintf(stderr, "nbrdf_example: loading a missing file should fail with NBRDF_ERROR_IO\n");
        return 1;
    }

    nbrdf_sampler_free(sampler);
    nbrdf_material_free(material);
    printf("ok\n");
    return 0;
}
