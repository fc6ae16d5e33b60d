// The scenes of render-fixture/scenes/, embedded at build time (see EmbedScenes.cmake).
#pragma once

namespace mcstat::render {

struct BuiltinScene {
    const char* name;  ///< file name without .json
    const char* json;
};

extern const BuiltinScene kBuiltinScenes[];
extern const int kBuiltinSceneCount;

}  // namespace mcstat::render
