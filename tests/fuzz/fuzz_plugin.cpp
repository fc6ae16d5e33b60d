// Fuzz target: the OpenImageIO plugin's open and read path (oiio-plugin/mcstatinput.cpp, compiled
// into this program rather than loaded, so its coverage counts): valid_file, open, and a float read
// of every subimage, as oiiotool and iv do. Errors must be one line naming the file.
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>

#include <cstdlib>
#include <memory>
#include <vector>

#include "fuzz_support.h"

// The plugin's factory (extern "C", so its namespace does not matter).
extern "C" OIIO::ImageInput* mcstat_input_imageio_create();

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    // Nothing kept between inputs: each one computes its subimages again (and memory stays flat).
    setenv("MCSTAT_PLUGIN_CACHE_MB", "0", 1);
    return 0;
}

namespace {

void requirePluginError(const std::string& path, const std::string& err) {
    mcstat::fuzz::require(!err.empty(), "plugin failed without an error", path);
    mcstat::fuzz::require(err.find(path) != std::string::npos,
                          "plugin error does not name the file", err);
    mcstat::fuzz::require(err.find('\n') == std::string::npos, "plugin error of more than one line",
                          mcstat::oneLine(err));
    mcstat::fuzz::requirePrintable(err, "plugin error holds a control byte or invalid UTF-8");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    const mcstat::fuzz::InputFile file(data, size);
    std::unique_ptr<OIIO::ImageInput> in(mcstat_input_imageio_create());
    mcstat::fuzz::require(in != nullptr, "plugin create", file.path());
    (void)in->valid_file(file.path());
    OIIO::ImageSpec spec;
    if (!in->open(file.path(), spec)) {
        requirePluginError(file.path(), in->geterror());
        return 0;
    }
    for (int sub = 0; in->seek_subimage(sub, 0); ++sub) {
        const OIIO::ImageSpec& s = in->spec();
        mcstat::fuzz::require(s.width > 0 && s.height > 0 && s.nchannels > 0, "empty subimage",
                              file.path());
        // The attributes the plugin composes from the file (oiiotool --info -v prints them).
        for (const OIIO::ParamValue& p : s.extra_attribs)
            if (p.type() == OIIO::TypeString &&
                OIIO::Strutil::starts_with(p.name().string(), "mcstat:"))
                mcstat::fuzz::requirePrintable(p.get_string(), "plugin attribute not printable");
        std::vector<float> pixels(size_t(s.image_pixels()) * size_t(s.nchannels));
        if (!in->read_image(sub, 0, 0, s.nchannels, OIIO::TypeFloat, pixels.data()))
            requirePluginError(file.path(), in->geterror());
    }
    in->close();
    return 0;
}
