// Fuzz target: the fixture renderer's scene JSON parser (render-fixture/SCENES.md). Every input is
// either a scene or a one-line error naming the source.
#include <string>

#include "fuzz_support.h"
#include "mcstat/render-fixture/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    const std::string text(reinterpret_cast<const char*>(data), size);
    mcstat::render::Scene scene;
    std::string err;
    if (!mcstat::render::parseScene(text, "fuzz.json", scene, err))
        mcstat::fuzz::requireOneLineError("fuzz.json", err);
    return 0;
}
