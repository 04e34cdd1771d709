// strata from C++: the same oracle as gradient.c, written as a lambda and
// wrapped by a small adapter (the header is plain C with extern "C").
// capi/tests/api/c_program.rs builds it with the system C++ compiler and checks
// its film against the Rust API's, bit for bit.
#include <cstdio>
#include <memory>
#include <vector>

#include "strata.h"

template <typename F> struct LambdaOracle {
    F trace;
    StrataOracle oracle;

    LambdaOracle(uint32_t width, uint32_t height, F f) : trace(f) {
        oracle = StrataOracle{width, height, this, &LambdaOracle::call, nullptr};
    }
    static void call(void *user, float x, float y, StrataSampler *sampler, float temperature,
                     float *rgb) {
        static_cast<LambdaOracle *>(user)->trace(x, y, sampler, temperature, rgb);
    }
};

int main(int argc, char **argv) {
    if (argc != 3) {
        std::fprintf(stderr, "usage: %s METHOD OUT\n", argv[0]);
        return 2;
    }
    const float width = 16, height = 12;
    LambdaOracle oracle(16, 12, [=](float x, float y, StrataSampler *s, float, float *rgb) {
        rgb[0] = x / width;
        rgb[1] = y / height;
        rgb[2] = strata_sampler_next_1d(s);
        if (rgb[2] < 0.25f) {
            float sx = x + 8.0f;
            const float splat[3] = {rgb[2], 0.0f, 0.0f};
            strata_sampler_splat(s, sx >= 16.0f ? sx - 16.0f : sx, y, splat);
        }
    });
    std::unique_ptr<StrataSettings, void (*)(StrataSettings *)> settings(
        strata_settings_new(argv[1]), strata_settings_free);
    if (!settings) {
        std::fprintf(stderr, "error: %s\n", strata_last_error());
        return 1;
    }
    strata_settings_set_seed(settings.get(), 7);
    strata_settings_set_samples_per_pixel(settings.get(), 160);
    strata_settings_set_threads(settings.get(), 2);
    StrataFilm *raw = nullptr;
    if (strata_render(&oracle.oracle, settings.get(), nullptr, &raw) != STRATA_STATUS_OK) {
        std::fprintf(stderr, "error: %s\n", strata_last_error());
        return 1;
    }
    std::unique_ptr<StrataFilm, void (*)(StrataFilm *)> film(raw, strata_film_free);
    size_t n = size_t(strata_film_width(film.get())) * strata_film_height(film.get()) * 3;
    std::FILE *out = std::fopen(argv[2], "wb");
    if (!out || std::fwrite(strata_film_data(film.get()), sizeof(double), n, out) != n) {
        return 1;
    }
    std::fclose(out);
    return 0;
}
