// Colour management through OpenColorIO. When $OCIO is unset the project's own small config is used
// (scene-linear Rec.709 primaries, an sRGB display with a "Standard" view): OCIO 2.1 on Debian 12
// has no built-in configs. When $OCIO is set, that config is honoured.
#pragma once

#include <array>
#include <string>

namespace mcstat {

/// Name of the scene-linear colour space every statistics file stores in (with the built-in
/// config).
inline constexpr const char* kSceneLinear = "lin_rec709";

/// Luminance weights of the working space `space` (a statistics file's mcstat:colorSpace, an
/// image's oiio:ColorSpace; any name findWorkingSpace knows, color_space.h): the active config's
/// luma (Config::getDefaultLumaCoefs) when the config's scene_linear colour space is `space` and
/// its luma agrees with the space's primaries (to 1e-3: the built-in config's 0.2126, 0.7152,
/// 0.0722 for lin_rec709), else the Y row of the RGB-to-XYZ matrix from the space's
/// chromaticities (SMPTE RP 177), with a warning when the config's luma was set aside (ACES
/// configs give Rec.709's luma for ACEScg). Every luminance weight in mcstat comes from here.
/// False with `err` ("colour space 'X' is unknown; known: ...") for a space mcstat cannot place.
/// A broken $OCIO config file falls back to the built-in one, and `warning` (if non-null) says so;
/// an `ocio://` URI in $OCIO that this OCIO cannot give (before 2.2) is an error naming the version
/// needed, here and in every function below that uses the config.
bool lumaCoefficients(const std::string& space, std::array<double, 3>& luma, std::string& err,
                      std::string* warning = nullptr);

/// lumaCoefficients of kSceneLinear (lin_rec709, the default working space), for tests; when the
/// config is unusable, the Y row of Rec.709's primaries with the error in `warning`. A file's own
/// space, and everything but tests, goes through the function above.
std::array<double, 3> lumaCoefficients(std::string* warning = nullptr);

/// Makes the OCIO config `path` the active one (oiiotool's --colorconfig), instead of $OCIO or
/// the built-in config, for everything after the call. An `ocio://` URI needs OCIO's built-in
/// configs (OpenColorIO 2.2): with an older OCIO it is refused with a one-line error naming the
/// version needed. False with `err` when the config cannot be read or is invalid.
bool setColorConfig(const std::string& path, std::string& err);

/// The OpenColorIO version mcstat is built with ("2.1.2").
std::string ocioVersion();

/// Text of the built-in config (for docs and tests).
const char* builtinOcioConfig();

/// The note applyDisplayTransform gives pixels of working space `space` with the default display
/// and view ("ACEScg shown through a matrix to lin_rec709 ..."), or "" when the config shows the
/// space itself: what a command prints once before review pictures of such pixels.
std::string displayNote(const std::string& space);

/// What the active config's file rules (OCIO Config::getColorSpaceFromFilepath) say of `path`:
/// `ocioName` is the config's colour space when a rule other than the Default one matches ("" when
/// only the Default rule does); `space` its working space (findWorkingSpace of its name or one of
/// its aliases) when that is scene-linear and known, else ""; `sceneLinear` whether its encoding
/// is scene-linear (OCIO's "scene-linear", or none given) and not data. False with `err` when the
/// config is unusable.
bool fileRuleColorSpace(const std::string& path, std::string& ocioName, std::string& space,
                        bool& sceneLinear, std::string& err);

/// Converts interleaved RGB scene-linear pixels in place to display-encoded values through the
/// active config's display/view transform (default display and view when empty).
/// Returns false with `err` set when the config or the transform cannot be built.
/// `space` is the pixels' working space (color_space.h; empty: the config's scene_linear): a space
/// the config has goes through the config (an ACES config and ACEScg); otherwise a matrix from its
/// chromaticities to the config's scene-linear space comes first, and `note` (if non-null) says so.
bool applyDisplayTransform(float* rgb, long npixels, std::string& err,
                           const std::string& display = "", const std::string& view = "",
                           const std::string& space = "", std::string* note = nullptr);

/// The colour space toSceneLinear converts to, as the active config names it: kSceneLinear (the
/// colour space of every statistics file) when the config has it, else its scene_linear role.
std::string sceneLinearName();

/// Converts interleaved RGB pixels in place from colour space `from` (a name of the active config,
/// or OIIO's "oiio:ColorSpace" names for linear data: "Linear", "linear", "lin_srgb",
/// "lin_rec709", "scene_linear") to sceneLinearName()'s colour space. `converted` is false when
/// nothing had to change (already scene-linear, or a data space). Returns false with `err` when
/// the config has no colour space `from` or the transform cannot be built.
bool toSceneLinear(float* rgb, long npixels, const std::string& from, bool& converted,
                   std::string& err);

}  // namespace mcstat
