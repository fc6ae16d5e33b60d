// Working colour spaces of scene-linear RGB: what a render's pixels mean, read from its metadata
// (colorInteropID, chromaticities, oiio:ColorSpace), kept in the statistics file and used for its
// luminance. Pure arithmetic, no OCIO (color.h adds the config). docs/color.md describes the
// rules.
#pragma once

#include <array>
#include <string>
#include <vector>

namespace mcstat {

/// CIE 1931 xy of the red, green and blue primaries and of the white point, in OpenEXR's order
/// (the `chromaticities` attribute: red, green, blue, white).
struct Chromaticities {
    double rx = 0, ry = 0, gx = 0, gy = 0, bx = 0, by = 0, wx = 0, wy = 0;
};

/// A scene-linear working space mcstat knows by name.
struct WorkingSpace {
    const char* name;       ///< mcstat:colorSpace (the name the ACES and mcstat OCIO configs use)
    const char* interopID;  ///< OpenEXR 3.4 colorInteropID (ASWF Color Interop Forum)
    const char* label;      ///< for messages: "ACEScg (AP1 primaries, ACES white)"
    Chromaticities xy;
};

/// The spaces known by name: lin_rec709 (ITU-R BT.709 primaries, D65), ACEScg (AP1, ACES
/// S-2014-004), ACES2065-1 (AP0, SMPTE ST 2065-1), lin_p3d65 (SMPTE EG 432-1 Display P3),
/// lin_rec2020 (ITU-R BT.2020).
const std::vector<WorkingSpace>& workingSpaces();

/// The space named `name` (case-insensitive): its mcstat name, its colorInteropID, or a common
/// alias (acescg/ap1, aces/ap0, rec709/srgb_linear/linear, p3/displayp3, rec2020); null if none.
const WorkingSpace* findWorkingSpace(const std::string& name);

/// "lin_rec709, ACEScg, ACES2065-1, lin_p3d65, lin_rec2020": for messages.
std::string knownWorkingSpaceNames();

/// The known space whose chromaticities are these within `tolerance` in x and y (files store
/// them as float, some writers round to 3 or 4 digits); null if none.
const WorkingSpace* matchChromaticities(const Chromaticities& c, double tolerance = 5e-4);

/// "R 0.713 0.293, G 0.165 0.83, B 0.128 0.044, W 0.32168 0.33767" for messages.
std::string chromaticitiesText(const Chromaticities& c);

/// The normalised primary matrix RGB -> XYZ of SMPTE RP 177-1993 (eq. 3.3-3.5): the primaries'
/// XYZ (Y = 1) as columns, scaled so that RGB (1, 1, 1) gives the white point with Y = 1. False
/// when the chromaticities are degenerate (a y of 0, collinear primaries, non-finite values).
bool rgbToXyz(const Chromaticities& c, std::array<std::array<double, 3>, 3>& m);

/// The matrix converting linear RGB of space `from` to space `to`: XYZ through rgbToXyz, with
/// the Bradford chromatic adaptation between the white points when they differ (as the ACES
/// reference configs convert Rec.709 to ACEScg). False as rgbToXyz.
bool rgbToRgb(const Chromaticities& from, const Chromaticities& to,
              std::array<std::array<double, 3>, 3>& m);

/// Luminance weights of a space: the Y row of rgbToXyz (so that Y = w . RGB, and w sums to 1).
/// False as rgbToXyz.
bool lumaFromChromaticities(const Chromaticities& c, std::array<double, 3>& luma);

/// The one luminance of scene-linear RGB every part of mcstat computes (estimators' ranking keys,
/// compare, metrics, review pictures, ingest checks): w . (r, g, b) in double, left to right.
/// `w` is the working space's luma (lumaCoefficients(space) in color.h).
inline double luminance(const std::array<double, 3>& w, double r, double g, double b) {
    return w[0] * r + w[1] * g + w[2] * b;
}
inline double luminance(const std::array<double, 3>& w, const float* rgb) {
    return luminance(w, double(rgb[0]), double(rgb[1]), double(rgb[2]));
}

}  // namespace mcstat
