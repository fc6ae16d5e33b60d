// What random parameter filtering (Sen and Darabi 2011, section 3.1) needs from the fixture
// renderer: a thin lens (depth of field), motion blur, a procedural checker texture, the new
// built-in scenes, and the per-sample random parameters and second-hit features of PathSample.
// Every expected value is derived by hand or analytically in the comment above its check.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "builtin_scenes.h"
#include "integrator.h"
#include "mcstat/render-fixture/render.h"
#include "mcstat/render-fixture/scene.h"
#include "render_test_util.h"
#include "rng.h"
#include "sampling.h"

namespace {

using mcstat::StatsImage;
using namespace mcstat::render;
using namespace mcstat::render::testutil;
using mcstat::render::render;

Scene mustParse(const std::string& json) {
    Scene s;
    std::string err;
    EXPECT_TRUE(parseScene(json, "test.json", s, err)) << err;
    return s;
}

std::vector<float> mustReference(const Scene& scene, const RenderOptions& opt) {
    std::vector<float> rgb;
    std::string err;
    EXPECT_TRUE(renderReference(scene, opt, rgb, err)) << err;
    return rgb;
}

std::string builtinJson(const std::string& name) {
    for (int i = 0; i < kBuiltinSceneCount; ++i)
        if (name == kBuiltinScenes[i].name) return kBuiltinScenes[i].json;
    ADD_FAILURE() << "no built-in scene " << name;
    return {};
}

/// Replaces every occurrence of `from`; returns how many there were.
int replaceAll(std::string& s, const std::string& from, const std::string& to) {
    int n = 0;
    for (size_t at = s.find(from); at != std::string::npos; at = s.find(from, at + to.size())) {
        s.replace(at, from.size(), to);
        ++n;
    }
    return n;
}

/// The render's own sampling pipeline, to look at individual PathSamples.
struct Sampler {
    const Scene& scene;
    Accel accel;
    LightSet lights;
    Camera camera;
    PathIntegrator integrator;

    explicit Sampler(const Scene& s)
        : scene(s),
          lights(s),
          camera(s.camera, s.width, s.height, s.hasMotion()),
          integrator(s, accel, lights) {
        std::string err;
        EXPECT_TRUE(accel.build(s, err)) << err;
    }
    PathSample sample(uint64_t seed, int x, int y, int64_t i) const {
        return samplePixel(camera, integrator, scene.width, seed, x, y, i);
    }
};

// ---------------------------------------------------------------------------------------------
// Scene keys

TEST(RpfScene, BuiltinScenesSayWhetherTheyHaveLensOrMotion) {
    for (const char* n : {"default", "tiny", "furnace", "caustic", "arealight", "texture"}) {
        const Scene s = mustLoad(n);
        EXPECT_FALSE(s.hasLens()) << n;
        EXPECT_FALSE(s.hasMotion()) << n;
    }
    const Scene dof = mustLoad("dof");
    EXPECT_TRUE(dof.hasLens());
    EXPECT_FALSE(dof.hasMotion());
    EXPECT_EQ(dof.camera.aperture, 0.2);
    // No focusDistance key: the camera focuses at |lookAt - position| = |(0, 0, -3.6)|.
    EXPECT_EQ(dof.camera.focusDistance, 0.0);
    EXPECT_DOUBLE_EQ(Camera(dof.camera, dof.width, dof.height).focusDistance(), 3.6);
    const Scene motion = mustLoad("motion");
    EXPECT_FALSE(motion.hasLens());
    EXPECT_TRUE(motion.hasMotion());
    for (const char* n : {"arealight", "dof", "motion", "texture"}) {
        const Scene s = mustLoad(n);
        EXPECT_EQ(s.width, 256) << n;
        EXPECT_EQ(s.height, 256) << n;
    }
    const Scene tex = mustLoad("texture");
    size_t textured = 0;
    for (const Material& m : tex.materials) textured += m.texture.type == TextureType::Checker;
    EXPECT_EQ(textured, 2u);
}

std::string parseError(const std::string& json) {
    Scene s;
    std::string err;
    EXPECT_FALSE(parseScene(json, "bad.json", s, err));
    EXPECT_EQ(err.find('\n'), std::string::npos) << err;
    return err;
}

TEST(RpfScene, BadLensMotionAndTextureKeysAreNamed) {
    const std::string base = R"({"image":{"width":4,"height":4},
      "camera":{"position":[0,0,0],"lookAt":[0,0,-1]CAM},
      "materials":{"m":{"type":MAT}},
      "shapes":[{"type":"sphere","material":"m","center":[0,0,-3],"radius":1SHAPE}]})";
    auto scene = [&](const std::string& cam, const std::string& mat, const std::string& shape) {
        std::string j = base;
        replaceAll(j, "CAM", cam);
        replaceAll(j, "MAT", mat);
        replaceAll(j, "SHAPE", shape);
        return j;
    };
    auto error = [&](const std::string& cam, const std::string& mat, const std::string& shape) {
        return parseError(scene(cam, mat, shape));
    };
    const std::string diffuse = R"("diffuse")";
    auto has = [](const std::string& err, const std::string& what) {
        return err.find(what) != std::string::npos;
    };
    EXPECT_TRUE(has(error(R"(,"aperture":-0.1)", diffuse, ""),
                    "bad.json: camera.aperture: must be non-negative"));
    EXPECT_TRUE(has(error(R"(,"focusDistance":0)", diffuse, ""),
                    "bad.json: camera.focusDistance: must be positive"));
    EXPECT_TRUE(has(error("", diffuse, R"(,"velocity":[1,0,0],"emission":[1,1,1])"),
                    "bad.json: shapes[0].velocity: emitters must be static"));
    EXPECT_TRUE(has(error("", diffuse, R"(,"velocity":[1,0])"),
                    "bad.json: shapes[0].velocity: expected an array of 3 numbers"));
    EXPECT_TRUE(has(error("", R"("diffuse","texture":{"type":"marble"})", ""),
                    "materials.m.texture.type: unknown texture type \"marble\""));
    EXPECT_TRUE(
        has(error("", R"("diffuse","texture":{"type":"checker","scale":0,"albedo2":[0,0,0]})", ""),
            "materials.m.texture.scale: must be positive"));
    EXPECT_TRUE(
        has(error("", R"("diffuse","texture":{"type":"checker","scale":1,"albedo2":[2,0,0]})", ""),
            "materials.m.texture.albedo2: components must lie in [0, 1]"));
    EXPECT_TRUE(has(error("", R"("diffuse","texture":{"type":"checker","scale":1})", ""),
                    "materials.m.texture: missing \"albedo2\""));
    // Only diffuse materials take a texture.
    EXPECT_TRUE(has(error("", R"("glass","texture":{"type":"checker"})", ""),
                    "materials.m: unknown key \"texture\""));
    // A zero velocity on an emitter is static, hence allowed.
    EXPECT_FALSE(
        mustParse(scene("", diffuse, R"(,"velocity":[0,0,0],"emission":[1,1,1])")).hasMotion());
}

// ---------------------------------------------------------------------------------------------
// Existing scenes are unchanged: a zero aperture and zero velocities draw nothing extra.

TEST(RpfIdentity, ZeroApertureAndZeroVelocityRenderBitForBit) {
    const std::string plain = builtinJson("tiny");
    std::string keyed = plain;
    ASSERT_EQ(
        replaceAll(keyed, R"("fov": 50})", R"("fov": 50, "aperture": 0, "focusDistance": 1.5})"),
        1);
    // Every shape, the emitters too (a zero velocity is static).
    ASSERT_EQ(
        replaceAll(keyed, R"({"type": "quad", )", R"({"type": "quad", "velocity": [0, 0, 0], )"),
        6);
    ASSERT_EQ(replaceAll(keyed, R"({"type": "sphere", )",
                         R"({"type": "sphere", "velocity": [0, 0, 0], )"),
              3);
    const Scene a = mustParse(plain), b = mustParse(keyed);
    EXPECT_FALSE(b.hasLens());
    EXPECT_FALSE(b.hasMotion());
    EXPECT_EQ(b.camera.focusDistance, 1.5);
    expectIdentical(mustRender(a, options(8, 2, 3)), mustRender(b, options(8, 2, 3)));
    EXPECT_TRUE(sameBits(mustReference(a, options(8, 1, 4)), mustReference(b, options(8, 1, 4))));
}

// ---------------------------------------------------------------------------------------------
// Thin lens

/// An emissive sphere (radiance 1, radius r) on the axis at distance d of a camera at the origin
/// looking down -z with a lens of radius A focused at distance f; black background, maxDepth 0
/// (only the emitter is seen).
Scene lensScene(double A, double f, double d, double r, int size, double fovDeg) {
    const std::string j = R"({"image":{"width":)" + std::to_string(size) + R"(,"height":)" +
                          std::to_string(size) + R"(},
      "camera":{"position":[0,0,0],"lookAt":[0,0,-1],"fov":)" +
                          std::to_string(fovDeg) + R"(,"aperture":)" + std::to_string(A) +
                          R"(,"focusDistance":)" + std::to_string(f) + R"(},
      "integrator":{"maxDepth":0},
      "materials":{},
      "shapes":[{"type":"sphere","emission":[1,1,1],"center":[0,0,)" +
                          std::to_string(-d) + R"(],"radius":)" + std::to_string(r) + "}]}";
    return mustParse(j);
}

/// Pixel (px, py)'s nearest and farthest distance from the image centre, in units of the plane in
/// focus (the pinhole ray through raster (x, y) meets it at ((2x/W - 1), (1 - 2y/H)) * f tan(fov/2)
/// for a square image).
struct PixelSpan {
    double nearest, farthest;
};
PixelSpan pixelSpan(int px, int py, int size, double unitsPerPixel) {
    const double c = size / 2.0;
    const double x0 = px - c, x1 = px + 1 - c, y0 = py - c, y1 = py + 1 - c;
    const double nx = x0 > 0 ? x0 : (x1 < 0 ? -x1 : 0), ny = y0 > 0 ? y0 : (y1 < 0 ? -y1 : 0);
    const double fx = std::max(std::abs(x0), std::abs(x1)),
                 fy = std::max(std::abs(y0), std::abs(y1));
    return {std::hypot(nx, ny) * unitsPerPixel, std::hypot(fx, fy) * unitsPerPixel};
}

TEST(RpfLens, OutOfFocusPointImagesAsTheCircleOfConfusion) {
    // Thin lens, lens radius A, focus distance f; a point at distance d images on the plane in
    // focus as a uniform disc of radius R_coc = A |1 - f / d| (the rays from every lens point
    // through it). A sphere of radius r there has the pinhole image radius R_img = r f / d, so
    // its image is the disc R_coc convolved with the disc R_img: zero beyond R_coc + R_img, and
    // uniform within R_coc - R_img, where a focus-plane point sees it through a sub-disc of the
    // lens of radius r f / |d - f|: value (r f / (A |d - f|))^2. The image's total flux is the
    // pinhole's, pi R_img^2 (every lens point sees the same disc, shifted).
    const double A = 0.2, f = 2, r = 0.05, fov = 14;
    const int size = 96;  // the near image's support, radius 0.175, is 34 pixels
    const double unitsPerPixel = 2 * f * std::tan(fov / 2 * kPi / 180) / size;
    const int64_t spp = 128;
    for (const double d : {4.0, 4.0 / 3.0}) {  // beyond the focus plane, and before it
        SCOPED_TRACE("d = " + std::to_string(d));
        const Scene s = lensScene(A, f, d, r, size, fov);
        const std::vector<float> img = mustReference(s, options(spp, 1));
        const double Rcoc = A * std::abs(1 - f / d), Rimg = r * f / d;
        const double inside = std::pow(r * f / (A * std::abs(d - f)), 2);
        // Far: R_coc 0.1, R_img 0.025, inside 1/16. Near: R_coc 0.1, R_img 0.075, inside 9/16.
        double sumInside = 0, flux = 0, fluxVar = 0;
        int nInside = 0, nOutside = 0;
        for (int py = 0; py < size; ++py)
            for (int px = 0; px < size; ++px) {
                const double v = img[(size_t(py) * size + size_t(px)) * 3];
                const PixelSpan span = pixelSpan(px, py, size, unitsPerPixel);
                flux += v;
                fluxVar += v * (1 - v) / double(spp);  // each sample is 0 or 1
                // 1% for the small-angle approximations, and one pixel of margin.
                if (span.nearest > 1.01 * (Rcoc + Rimg) + unitsPerPixel) {
                    ++nOutside;
                    EXPECT_EQ(v, 0.0f) << "pixel " << px << "," << py;
                } else if (span.farthest < 0.99 * (Rcoc - Rimg) - 0.5 * unitsPerPixel) {
                    ++nInside;
                    sumInside += v;
                }
            }
        ASSERT_GT(nInside, 20);
        ASSERT_GT(nOutside, size * size / 2);
        // Samples are 0 or 1 with probability `inside`: binomial standard error.
        const double meanInside = sumInside / nInside;
        const double se = std::sqrt(inside * (1 - inside) / (double(nInside) * double(spp)));
        EXPECT_NEAR(meanInside, inside, 4 * se + 0.01 * inside);
        EXPECT_LT(4 * se, 0.15 * inside);  // tight enough to tell 1/16 and 9/16 from others
        const double expectedFlux = kPi * Rimg * Rimg / (unitsPerPixel * unitsPerPixel);
        EXPECT_NEAR(flux, expectedFlux, 4 * std::sqrt(fluxVar) + 0.01 * expectedFlux);
    }
}

TEST(RpfLens, PointAtTheFocusDistanceStaysSharp) {
    // A sphere centred on the plane in focus: every ray through a focus-plane point inside its
    // great circle (radius r) passes through the sphere there, whatever the lens point, so those
    // pixels are exactly 1; beyond the circle the rays can only clip the sphere within
    // (A + r) r / f of it (0.006 here, about one pixel), so pixels two pixels out are exactly 0.
    const double A = 0.2, f = 2, r = 0.05, fov = 10;
    const int size = 64;
    const double unitsPerPixel = 2 * f * std::tan(fov / 2 * kPi / 180) / size;
    const std::vector<float> img = mustReference(lensScene(A, f, f, r, size, fov), options(32, 1));
    int ones = 0, zeros = 0;
    for (int py = 0; py < size; ++py)
        for (int px = 0; px < size; ++px) {
            const float v = img[(size_t(py) * size + size_t(px)) * 3];
            const PixelSpan span = pixelSpan(px, py, size, unitsPerPixel);
            if (span.farthest < r - 0.5 * unitsPerPixel) {
                ++ones;
                EXPECT_EQ(v, 1.0f) << "pixel " << px << "," << py;
            } else if (span.nearest > r + 2 * unitsPerPixel) {
                ++zeros;
                EXPECT_EQ(v, 0.0f) << "pixel " << px << "," << py;
            }
        }
    // r is 9.1 pixels: 208 pixels lie inside r - 0.5 pixel.
    EXPECT_EQ(ones, 208);
    EXPECT_GT(zeros, size * size / 2);
}

// ---------------------------------------------------------------------------------------------
// Motion blur

TEST(RpfMotion, PixelIsTheFractionOfTheShutterLeftUncovered) {
    // Background 1; a black quad covering x <= e(t) = -8 + 16 t on the plane z = -5, in front of a
    // camera at the origin looking down -z (fov 90, 40 x 10 pixels, so pixel column px sees
    // x in [px - 20, px - 19) there). A point x is covered while e(t) >= x, i.e. for
    // t >= (x + 8) / 16, so it shows the background for the fraction (x + 8) / 16 of the shutter:
    // columns 12..27, entirely inside the ramp, average (px - 11.5) / 16; columns <= 11 are always
    // covered (exactly 0), columns >= 28 never (exactly 1).
    const Scene s = mustParse(R"({"image":{"width":40,"height":10},
      "camera":{"position":[0,0,0],"lookAt":[0,0,-1],"fov":90},
      "background":[1,1,1],
      "materials":{},
      "shapes":[{"type":"quad","corner":[-100,-100,-5],"edge1":[92,0,0],"edge2":[0,200,0],
                 "velocity":[16,0,0]}]})");
    ASSERT_TRUE(s.hasMotion());
    const int64_t spp = 256;
    const std::vector<float> img = mustReference(s, options(spp, 1));
    for (int px = 0; px < 40; ++px) {
        double sum = 0;
        for (int py = 0; py < 10; ++py) {
            const float v = img[(size_t(py) * 40 + size_t(px)) * 3];
            sum += v;
            if (px <= 11) {
                EXPECT_EQ(v, 0.0f) << px << "," << py;
            } else if (px >= 28) {
                EXPECT_EQ(v, 1.0f) << px << "," << py;
            }
        }
        if (px >= 12 && px <= 27) {
            // Each sample is 0 or 1: binomial standard error of the column's 2,560 samples.
            const double p = (px - 11.5) / 16, n = 10.0 * double(spp);
            EXPECT_NEAR(sum / 10, p, 5 * std::sqrt(p * (1 - p) / n)) << "column " << px;
        }
    }
}

TEST(RpfMotion, ShadowRaysSeeTheOccluderAtTheSampleTime) {
    // A tiny light (0.02 wide, at height 2) over a diffuse floor; a black slab at height 1 covering
    // x in [-3.5 + t, -0.5 + t] (it moves 1 to the right over the shutter). The shadow ray from
    // floor point p to light point q crosses height 1 at m = (p + q) / 2, which the slab covers
    // for t >= m.x + 0.5: the floor sees the light for the fraction m.x + 0.5 of the shutter. The
    // view is symmetric about x = 0 (so is the light), hence the image mean is exactly half the
    // mean without the slab. maxDepth 1: direct light only. If shadow rays used time 0 the slab
    // (then at [-3.5, -0.5]) would never shadow the view, and the ratio would be about 1.
    const std::string withSlab = R"({"image":{"width":32,"height":32},
      "camera":{"position":[0,0.5,3],"lookAt":[0,0,0],"fov":8},
      "integrator":{"maxDepth":1},
      "materials":{"m":{"type":"diffuse","albedo":[0.5,0.5,0.5]}},
      "shapes":[
        {"type":"quad","material":"m","corner":[-5,0,-5],"edge1":[0,0,10],"edge2":[10,0,0]},
        {"type":"quad","emission":[1000,1000,1000],"corner":[-0.01,2,-0.01],"edge1":[0.02,0,0],
         "edge2":[0,0,0.02]}SLAB]})";
    std::string a = withSlab, b = withSlab;
    replaceAll(
        a, "SLAB",
        R"(,{"type":"quad","corner":[-3.5,1,-3],"edge1":[3,0,0],"edge2":[0,0,6],"velocity":[1,0,0]})");
    replaceAll(b, "SLAB", "");
    const std::vector<float> moving = mustReference(mustParse(a), options(16, 1));
    const std::vector<float> open = mustReference(mustParse(b), options(16, 1));
    double sumMoving = 0, sumOpen = 0;
    for (size_t i = 0; i < moving.size(); i += 3) sumMoving += moving[i], sumOpen += open[i];
    ASSERT_GT(sumOpen, 0);
    // 16,384 samples, each lit or shadowed with probability about 1/2: relative standard error
    // about 1 / sqrt(16384) = 0.008 of the ratio's numerator.
    EXPECT_NEAR(sumMoving / sumOpen, 0.5, 0.04);
}

// ---------------------------------------------------------------------------------------------
// Checker texture

TEST(RpfTexture, CheckerLookupAtKnownPoints) {
    Material m;
    m.albedo = Vec3(0.9, 0.5, 0.1);
    EXPECT_EQ(m.albedoAt(Vec3(0.6, 0.1, 0.1)).x, 0.9);  // untextured: the albedo everywhere
    m.texture.type = TextureType::Checker;
    m.texture.scale = 0.5;
    m.texture.albedo2 = Vec3(0.1, 0.3, 0.7);
    // Cells (floor(x/0.5), floor(y/0.5), floor(z/0.5)) and the parity of their sum:
    EXPECT_EQ(m.albedoAt(Vec3(0.1, 0.1, 0.1)).x, 0.9);     // (0, 0, 0): even, albedo
    EXPECT_EQ(m.albedoAt(Vec3(0.6, 0.1, 0.1)).x, 0.1);     // (1, 0, 0): odd, albedo2
    EXPECT_EQ(m.albedoAt(Vec3(-0.1, 0.1, 0.1)).x, 0.1);    // (-1, 0, 0): odd
    EXPECT_EQ(m.albedoAt(Vec3(-0.1, -0.1, 0.1)).x, 0.9);   // (-1, -1, 0): even
    EXPECT_EQ(m.albedoAt(Vec3(1.2, 0.7, -0.3)).x, 0.9);    // (2, 1, -1): even
    EXPECT_EQ(m.albedoAt(Vec3(1.2, 0.7, -0.6)).x, 0.1);    // (2, 1, -2): odd
    EXPECT_EQ(m.albedoAt(Vec3(-1.0, 0.0, 0.0)).x, 0.9);    // (-2, 0, 0): cells are [k s, (k+1) s)
    EXPECT_EQ(m.albedoAt(Vec3(-0.25, 0.0, 0.0)).z, 0.7);   // (-1, 0, 0): odd
    EXPECT_EQ(m.albedoAt(Vec3(0.0, -1e-12, 0.0)).z, 0.7);  // (0, -1, 0): odd
}

TEST(RpfTexture, TexturedPlaneUnderConstantSkyIsAlbedoTimesSky) {
    // A camera 1.3 above a textured diffuse floor y = 0, looking straight down (fov 90, 32 x 32,
    // up = -z): raster (x, y) sees the floor point 1.3 (x / 16 - 1, 0, y / 16 - 1). No lights,
    // sky B, maxDepth 1: each sample is albedo(p) * B exactly (the bounce's weight is the albedo,
    // every bounce escapes to the sky). Cells are 0.325 = 4 pixels wide with edges on pixel edges,
    // so each pixel lies in one cell: pixel (px, py) is albedo or albedo2 by the parity of
    // floor(px / 4) + floor(py / 4) (the two -4 offsets cancel), times B. The floor lies on a cell
    // boundary (y = 0): the lookup takes the plane's own y, else the rounding of hit points
    // (1.3 + d.y (-1.3 / d.y) is a few 1e-16 either side of 0) would flip the parity of random
    // samples. The albedo feature is the texture value.
    const Scene s = mustParse(R"({"image":{"width":32,"height":32},
      "camera":{"position":[0,1.3,0],"lookAt":[0,0,0],"up":[0,0,-1],"fov":90},
      "background":[0.5,0.25,1],
      "integrator":{"maxDepth":1},
      "materials":{"c":{"type":"diffuse","albedo":[0.9,0.5,0.1],
        "texture":{"type":"checker","scale":0.325,"albedo2":[0.1,0.3,0.7]}}},
      "shapes":[{"type":"quad","material":"c","corner":[-2,0,-2],"edge1":[0,0,4],
                 "edge2":[4,0,0]}]})");
    const StatsImage img = mustRender(s, options(16, 2));
    const Vec3 sky(0.5, 0.25, 1), a(0.9, 0.5, 0.1), b(0.1, 0.3, 0.7);
    int odd = 0;
    for (int py = 0; py < 32; ++py)
        for (int px = 0; px < 32; ++px) {
            const size_t p = size_t(py) * 32 + size_t(px);
            const bool isOdd = (px / 4 + py / 4) % 2 == 1;
            odd += isOdd;
            const Vec3 albedo = isOdd ? b : a;
            for (int c = 0; c < 3; ++c) {
                EXPECT_NEAR(img.mean[p * 3 + size_t(c)], albedo[c] * sky[c], 1e-6)
                    << px << "," << py;
                EXPECT_EQ(img.variance[p * 3 + size_t(c)], 0.0f) << px << "," << py;
                EXPECT_NEAR(img.albedo[p * 3 + size_t(c)], albedo[c], 1e-6) << px << "," << py;
            }
        }
    EXPECT_EQ(odd, 512);
}

// ---------------------------------------------------------------------------------------------
// Energy: the furnace stays Le / (1 - rho) = 2 with a lens and with motion

/// Image mean against `expected` within 4 standard errors (pixels are independent), and the
/// test tight enough to see a 1% error.
void expectImageMean(const StatsImage& img, double expected) {
    const size_t P = img.pixelCount();
    for (size_t c = 0; c < 3; ++c) {
        double sum = 0, varOverN = 0;
        for (size_t p = 0; p < P; ++p) {
            sum += img.mean[p * 3 + c];
            varOverN += img.variance[p * 3 + c] / img.count[p];
        }
        const double se = std::sqrt(varOverN) / double(P);
        EXPECT_NEAR(sum / double(P), expected, 4 * se) << "channel " << c;
        EXPECT_LT(4 * se, 0.01 * expected);
        EXPECT_GT(se, 0.0);
    }
}

TEST(RpfEnergy, FurnaceWithLensAndMotionStaysAnalytic) {
    // The furnace (camera at the centre of an emissive diffuse sphere, Le = 1, rho = 0.5): every
    // point inside sees radiance Le / (1 - rho) = 2 in every direction, so a lens (rays from other
    // points, other directions) changes nothing. A moving glass ball inside neither emits nor
    // absorbs: in a uniform radiance field it passes radiance through unchanged, so it changes
    // nothing either, while it exercises time sampling, motion-blur traversal and refinement.
    Scene s = mustLoad("furnace");
    s.camera.aperture = 0.3;
    s.camera.focusDistance = 0.6;
    const StatsImage lens = mustRender(s, options(256, 4));
    expectImageMean(lens, 2.0);

    Material glass;
    glass.name = "glass";
    glass.type = MaterialType::Glass;
    s.materials.push_back(glass);
    Shape ball;
    ball.type = ShapeType::Sphere;
    ball.center = Vec3(-0.2, 0, -0.5);
    ball.radius = 0.2;
    ball.material = int(s.materials.size()) - 1;
    ball.velocity = Vec3(0.4, 0.1, 0);
    s.shapes.push_back(ball);
    ASSERT_TRUE(s.hasMotion());
    const StatsImage moving = mustRender(s, options(256, 4));
    expectImageMean(moving, 2.0);
    // The ball is seen: the first hits' albedo feature is glass's 1 in some pixels, the
    // enclosure's 0.5 in others.
    const auto [lo, hi] = std::minmax_element(moving.albedo.begin(), moving.albedo.end());
    EXPECT_EQ(*lo, 0.5f);
    EXPECT_GT(*hi, 0.75f);
}

// ---------------------------------------------------------------------------------------------
// PathSample's random parameters and second-hit features

/// A closed box [-1, 1]^3 (two-sided white walls) with a light under its ceiling, a camera with
/// a lens inside it and a moving ball: every path's first bounce hits something.
const char* kClosedBox = R"({"image":{"width":8,"height":8},
  "camera":{"position":[0,0,0.8],"lookAt":[0,0,-1],"fov":70,"aperture":0.1},
  "integrator":{"maxDepth":8},
  "materials":{"w":{"type":"diffuse","albedo":[0.7,0.7,0.7]}},
  "shapes":[
    {"type":"box","material":"w","min":[-1,-1,-1],"max":[1,1,1]},
    {"type":"sphere","material":"w","center":[-0.3,-0.5,-0.3],"radius":0.2,"velocity":[0.5,0,0]},
    {"type":"quad","emission":[5,5,5],"corner":[-0.2,0.9,-0.2],"edge1":[0.4,0,0],"edge2":[0,0,0.4]}
  ]})";

TEST(RpfFeatures, RandomParametersAreTheNumbersDrawnInOrder) {
    // A sample's generator yields, in order: jitter x, jitter y, lens (2), time, then at the first
    // (diffuse) hit the light sample (light choice, point u, point v) and the bounce (u, v).
    const Scene s = mustParse(kClosedBox);
    ASSERT_TRUE(s.hasLens());
    ASSERT_TRUE(s.hasMotion());
    const Sampler sampler(s);
    for (int i = 0; i < 64; ++i) {
        const int x = i % 8, y = (i / 8) % 8;
        const PathSample ps = sampler.sample(7, x, y, i);
        Pcg32 rng = sampleRng(7, uint64_t(y) * 8 + uint64_t(x), uint64_t(i));
        double u[10];
        for (double& v : u) v = rng.uniform();
        EXPECT_EQ(ps.screenX, x + u[0]);
        EXPECT_EQ(ps.screenY, y + u[1]);
        const auto [du, dv] = sampleConcentricDisk(u[2], u[3]);
        EXPECT_EQ(ps.lensU, du);
        EXPECT_EQ(ps.lensV, dv);
        EXPECT_EQ(ps.time, u[4]);
        ASSERT_TRUE(ps.hit);
        EXPECT_EQ(ps.lightU, u[6]);
        EXPECT_EQ(ps.lightV, u[7]);
        EXPECT_EQ(ps.bounceU, u[8]);
        EXPECT_EQ(ps.bounceV, u[9]);
    }
    // Without lens and motion the path's numbers follow the jitter directly: tiny's first hits on
    // its diffuse walls have the light point at draws 3, 4 and the bounce at 5, 6.
    const Scene tiny = mustLoad("tiny");
    const Sampler plain(tiny);
    int diffuse = 0, glass = 0, mirror = 0;
    for (int i = 0; i < 200; ++i) {
        const int x = 4 + i % 16, y = 4 + (i / 16) % 8;
        const PathSample ps = plain.sample(3, x, y, i);
        EXPECT_EQ(ps.lensU, 0.0);
        EXPECT_EQ(ps.lensV, 0.0);
        EXPECT_EQ(ps.time, 0.0);
        Pcg32 rng = sampleRng(3, uint64_t(y) * uint64_t(tiny.width) + uint64_t(x), uint64_t(i));
        double u[7];
        for (double& v : u) v = rng.uniform();
        EXPECT_EQ(ps.screenX, x + u[0]);
        EXPECT_EQ(ps.screenY, y + u[1]);
        if (ps.lightNumbers == 2) {  // a light sample at the first hit: a diffuse surface
            ++diffuse;
            EXPECT_EQ(ps.lightU, u[3]);
            EXPECT_EQ(ps.lightV, u[4]);
            EXPECT_EQ(ps.bounceU, u[5]);
            EXPECT_EQ(ps.bounceV, u[6]);
        } else if (ps.hit && ps.albedo.x == 1.0) {  // glass: one number, reflect or refract
            ++glass;
            EXPECT_EQ(ps.bounceNumbers, 1);
            EXPECT_EQ(ps.bounceU, u[2]);
            EXPECT_NE(ps.bounceV, 0.0);             // unused: an independent filler number
        } else if (ps.hit && ps.albedo.x == 0.9) {  // mirror: no number at all
            ++mirror;
            EXPECT_EQ(ps.bounceNumbers, 0);
            EXPECT_EQ(ps.lightNumbers, 0);
        }
    }
    EXPECT_GT(diffuse, 100);
    EXPECT_GT(glass, 0);
    EXPECT_GT(mirror, 0);
}

TEST(RpfFeatures, FieldsAreInRangeAndTheSecondHitIsInsideTheBox) {
    const Scene s = mustParse(kClosedBox);
    const Sampler sampler(s);
    const int n = 4096;
    double sumR2 = 0, sumTime = 0;
    int checked = 0;
    for (int i = 0; i < n; ++i) {
        const int x = i % 8, y = (i / 8) % 8;
        const PathSample ps = sampler.sample(11, x, y, i);
        EXPECT_GE(ps.screenX, x);
        EXPECT_LT(ps.screenX, x + 1);
        EXPECT_GE(ps.screenY, y);
        EXPECT_LT(ps.screenY, y + 1);
        const double r2 = ps.lensU * ps.lensU + ps.lensV * ps.lensV;
        EXPECT_LE(r2, 1.0 + 1e-12);
        sumR2 += r2;
        EXPECT_GE(ps.time, 0.0);
        EXPECT_LT(ps.time, 1.0);
        sumTime += ps.time;
        for (double v : {ps.lightU, ps.lightV, ps.bounceU, ps.bounceV}) {
            EXPECT_GE(v, 0.0);
            EXPECT_LT(v, 1.0);
        }
        ASSERT_TRUE(ps.hit);
        ASSERT_TRUE(ps.hit2) << "a closed box: the first bounce always hits";
        for (int c = 0; c < 3; ++c) EXPECT_LE(std::abs(ps.position2[c]), 1.0 + 1e-9);
        EXPECT_NEAR(length(ps.normal2), 1.0, 1e-12);
        EXPECT_GT(length(ps.position2 - ps.position), 0.0);
        EXPECT_TRUE(ps.albedo.x == 0.7);
        // The second hit is where the direction chosen by (bounceU, bounceV) leads: a cosine-
        // weighted direction around the normal on the camera's side. The bounce leaves from a
        // point offset by at most 2e-4, so over more than 0.1 the direction agrees within 2e-3.
        const Vec3 nf =
            dot(ps.normal, s.camera.position - ps.position) > 0 ? ps.normal : -ps.normal;
        const Vec3 wi = Frame(nf).toWorld(sampleCosineHemisphere(ps.bounceU, ps.bounceV));
        const Vec3 seg = ps.position2 - ps.position;
        if (length(seg) > 0.1) {
            ++checked;
            EXPECT_LT(length(normalize(seg) - wi), 2e-3) << "sample " << i;
        }
    }
    EXPECT_GT(checked, n * 9 / 10);
    // Uniform on the disc: r^2 is uniform on [0, 1] (mean 1/2, variance 1/12); time uniform on
    // [0, 1) (mean 1/2, variance 1/12). 4 standard errors of 4,096 samples: 0.018.
    const double tol = 4 * std::sqrt(1.0 / 12 / n);
    EXPECT_NEAR(sumR2 / n, 0.5, tol);
    EXPECT_NEAR(sumTime / n, 0.5, tol);

    // maxDepth 0: no bounce, so neither light nor bounce numbers nor a second hit.
    Scene flat = s;
    flat.maxDepth = 0;
    const Sampler none(flat);
    for (int i = 0; i < 64; ++i) {
        const PathSample ps = none.sample(11, i % 8, i / 8, i);
        EXPECT_TRUE(ps.hit);
        EXPECT_FALSE(ps.hit2);
        EXPECT_EQ(ps.lightNumbers, 0);
        EXPECT_EQ(ps.bounceNumbers, 0);
        EXPECT_EQ(length(ps.position2), 0.0);
        // The unused numbers are the filler generator's, not zeros: they tell nothing.
        Pcg32 filler =
            sampleRng(~uint64_t(11), uint64_t((i / 8) * flat.width + i % 8), uint64_t(i));
        EXPECT_EQ(ps.lightU, filler.uniform());
        EXPECT_EQ(ps.lightV, filler.uniform());
        EXPECT_EQ(ps.bounceU, filler.uniform());
        EXPECT_EQ(ps.bounceV, filler.uniform());
    }
}

// ---------------------------------------------------------------------------------------------
// The new built-in scenes: identical bytes for any thread count

TEST(RpfScenes, NewScenesAreByteIdenticalForOneAndTwoThreads) {
    namespace fs = std::filesystem;
    const fs::path dir =
        fs::temp_directory_path() / ("mcstat_rpf_test_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    for (const char* name : {"arealight", "dof", "motion", "texture"}) {
        SCOPED_TRACE(name);
        Scene s = mustLoad(name);
        s.width = 48;
        s.height = 48;
        std::vector<std::string> bytes;
        for (int threads : {1, 2}) {
            const std::string path = (dir / (std::string(name) + std::to_string(threads))).string();
            std::string err;
            ASSERT_TRUE(mcstat::writeStatsFile(path, mustRender(s, options(4, 2, 5, threads)), err))
                << err;
            std::ifstream in(path, std::ios::binary);
            bytes.emplace_back(std::istreambuf_iterator<char>(in),
                               std::istreambuf_iterator<char>());
        }
        EXPECT_GT(bytes[0].size(), 48u * 48u * 4u);
        EXPECT_TRUE(bytes[0] == bytes[1]);
    }
    fs::remove_all(dir);
}

}  // namespace
