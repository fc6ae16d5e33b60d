// Test support: small EXRs named as real renderers name their channels (Blender/Cycles multilayer,
// pbrt-v4's GBufferFilm, Arnold-style AOV layers, plain RGB), written by the test itself.
#pragma once

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <functional>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace mcstat::testing {

/// A scratch directory per test under the build tree (tests/ingest/tmp-SUITE-TEST), removed
/// afterwards.
class ScratchDirTest : public ::testing::Test {
  protected:
    std::string dir;
    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        dir = std::string(MCSTAT_BINARY_DIR) + "/tests/ingest/tmp-" + info->test_suite_name() +
              "-" + info->name();
        OIIO::Filesystem::remove_all(dir);
        OIIO::Filesystem::create_directory(dir);
    }
    void TearDown() override { OIIO::Filesystem::remove_all(dir); }
    std::string path(const std::string& name) const { return dir + "/" + name; }
};

/// Value of channel `name` at pixel (x, y).
using ChannelFn = std::function<float(const std::string& name, int x, int y)>;

struct ExrSpec {
    int width = 8, height = 6;
    int x = 0, y = 0;  ///< data window origin
    std::vector<std::string> channels;
    std::map<std::string, std::string> stringAttrs;
    std::map<std::string, int> intAttrs;
    bool half = false;
};

/// Writes a single-part EXR; throws on failure (tests only).
inline void writeExr(const std::string& path, const ExrSpec& e, const ChannelFn& value) {
    OIIO::ImageSpec spec(e.width, e.height, int(e.channels.size()),
                         e.half ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT);
    spec.x = spec.full_x = e.x;
    spec.y = spec.full_y = e.y;
    spec.channelnames = e.channels;
    spec.alpha_channel = -1;
    spec.z_channel = -1;
    for (const auto& [k, v] : e.stringAttrs) spec.attribute(k, v);
    for (const auto& [k, v] : e.intAttrs) spec.attribute(k, v);
    std::vector<float> px(size_t(e.width) * e.height * e.channels.size());
    for (int yy = 0; yy < e.height; ++yy)
        for (int xx = 0; xx < e.width; ++xx)
            for (size_t c = 0; c < e.channels.size(); ++c)
                px[(size_t(yy) * e.width + xx) * e.channels.size() + c] =
                    value(e.channels[c], xx, yy);
    auto out = OIIO::ImageOutput::create(path);
    if (!out || !out->open(path, spec) || !out->write_image(OIIO::TypeDesc::FLOAT, px.data()) ||
        !out->close())
        throw std::runtime_error("cannot write " + path + ": " + OIIO::geterror());
}

/// Blender/Cycles 3.x multilayer channel names of one view layer: an AO pass that sorts before
/// Combined, Combined RGBA and the denoising data passes.
inline std::vector<std::string> cyclesChannels(const std::string& viewLayer = "ViewLayer") {
    std::vector<std::string> c;
    for (const char* s :
         {"AO.R", "AO.G", "AO.B", "Combined.R", "Combined.G", "Combined.B", "Combined.A",
          "Denoising Normal.X", "Denoising Normal.Y", "Denoising Normal.Z", "Denoising Albedo.R",
          "Denoising Albedo.G", "Denoising Albedo.B", "Denoising Depth.Z", "Depth.Z"})
        c.push_back(viewLayer + "." + s);
    return c;
}

/// pbrt-v4 GBufferFilm channel names (the dotted form of recent pbrt-v4).
inline std::vector<std::string> pbrtChannels() {
    return {"R",    "G",   "B",   "Albedo.R",   "Albedo.G",   "Albedo.B",  "P.X",  "P.Y",
            "P.Z",  "N.X", "N.Y", "N.Z",        "Ns.X",       "Ns.Y",      "Ns.Z", "dzdx",
            "dzdy", "u",   "v",   "Variance.R", "Variance.G", "Variance.B"};
}

/// pbrt-v4's earlier undotted names (Px, Nsx, ...).
inline std::vector<std::string> pbrtOldChannels() {
    return {"R",   "G",   "B",    "Albedo.R",   "Albedo.G",   "Albedo.B",  "Px",
            "Py",  "Pz",  "dzdx", "dzdy",       "Nx",         "Ny",        "Nz",
            "Nsx", "Nsy", "Nsz",  "Variance.R", "Variance.G", "Variance.B"};
}

/// Arnold/Karma/RenderMan-style AOV layers: the beauty in RGBA.*, a diffuse AOV, N, P, Z.
inline std::vector<std::string> aovChannels() {
    return {"RGBA.R", "RGBA.G", "RGBA.B", "RGBA.A", "diffuse.R", "diffuse.G", "diffuse.B",
            "N.X",    "N.Y",    "N.Z",    "P.X",    "P.Y",       "P.Z",       "Z"};
}

}  // namespace mcstat::testing
