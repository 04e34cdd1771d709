/* strata from C: renders a 16x12 analytic oracle (red = x / width, green =
 * y / height, blue = a uniform number the engine draws; paths whose number
 * is below 1/4 also splat it, in red, half the film to the right) with the
 * method named by argv[1] at 160 paths per pixel (above every method's
 * smallest budget on this film: ERPT's pass is 101, multi-stage MLT's 154),
 * seed 7, 2 threads, and writes the film's doubles to argv[2].
 * capi/tests/api/c_program.rs builds and runs it and compares the file with
 * the Rust API's render, bit for bit. */
#include <stdio.h>
#include "strata.h"

/* Pure: the same film point and numbers give the same radiance. */
static void trace(void *user, float x, float y, StrataSampler *sampler, float temperature,
                  float *rgb) {
    const StrataOracle *self = (const StrataOracle *)user;
    (void)temperature;
    rgb[0] = x / (float)self->width;
    rgb[1] = y / (float)self->height;
    rgb[2] = strata_sampler_next_1d(sampler);
    if (rgb[2] < 0.25f) {
        /* A contribution elsewhere on the film, as light tracing makes. */
        float sx = x + 8.0f;
        const float splat[3] = {rgb[2], 0.0f, 0.0f};
        strata_sampler_splat(sampler, sx >= 16.0f ? sx - 16.0f : sx, y, splat);
    }
}

/* What the observer saw. */
typedef struct {
    uint64_t reported;
    unsigned previews;
} Watch;

static int32_t progress(void *user, double fraction, uint64_t paths) {
    (void)fraction;
    ((Watch *)user)->reported = paths;
    return 0; /* non-zero would cancel */
}

/* The image so far: a real program would display or save it. */
static void preview(void *user, uint32_t width, uint32_t height, const double *rgb) {
    (void)width, (void)height, (void)rgb;
    ((Watch *)user)->previews += 1;
}

int main(int argc, char **argv) {
    if (argc != 3) {
        fprintf(stderr, "usage: %s METHOD OUT\n", argv[0]);
        return 2;
    }
    if (strata_settings_new("no-such-method") != NULL) {
        return 1;
    }
    printf("an unknown method: %s\n", strata_last_error());

    StrataOracle oracle = {16, 12, NULL, trace, NULL};
    oracle.user = &oracle;
    StrataSettings *settings = strata_settings_new(argv[1]);
    if (settings == NULL) {
        fprintf(stderr, "error: %s\n", strata_last_error());
        return 1;
    }
    strata_settings_set_seed(settings, 7);
    strata_settings_set_samples_per_pixel(settings, 160);
    strata_settings_set_threads(settings, 2);
    Watch watch = {0, 0};
    /* No set_up callback: the bootstrap is not reported. */
    StrataObserver observer = {&watch, progress, preview, 0.5, NULL};
    StrataFilm *film = NULL;
    StrataStatus status = strata_render(&oracle, settings, &observer, &film);
    strata_settings_free(settings);
    if (status != STRATA_STATUS_OK) {
        fprintf(stderr, "error: %s\n", strata_last_error());
        strata_film_free(film);
        return 1;
    }
    size_t n = (size_t)strata_film_width(film) * strata_film_height(film) * 3;
    FILE *out = fopen(argv[2], "wb");
    if (out == NULL || fwrite(strata_film_data(film), sizeof(double), n, out) != n) {
        fprintf(stderr, "error: cannot write %s\n", argv[2]);
        return 1;
    }
    fclose(out);
    StrataStats stats;
    strata_film_stats(film, &stats);
    printf("%s: %ux%u, %llu paths (last progress report %llu, %u previews), acceptance %.3f\n",
           argv[1], strata_film_width(film), strata_film_height(film),
           (unsigned long long)stats.paths, (unsigned long long)watch.reported, watch.previews,
           stats.acceptance_rate);
    strata_film_free(film);
    return 0;
}
