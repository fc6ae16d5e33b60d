// Working colour spaces (color_space.h).
#include "mcstat/core/color_space.h"

#include <strings.h>

#include <cmath>
#include <cstdio>

namespace mcstat {

const std::vector<WorkingSpace>& workingSpaces() {
    // Chromaticities as the standards publish them.
    static const std::vector<WorkingSpace> spaces = {
        // ITU-R BT.709-6 table 1 items 1.3-1.4: the sRGB primaries (IEC 61966-2-1), D65.
        {"lin_rec709",
         "lin_rec709_scene",
         "Rec.709 (sRGB primaries, D65)",
         {0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290}},
        // ACES S-2014-004 (ACEScg) section 4.1: AP1, ACES white (about D60).
        {"ACEScg",
         "lin_ap1_scene",
         "ACEScg (AP1 primaries, ACES white)",
         {0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767}},
        // SMPTE ST 2065-1:2012 section 4.2: AP0, ACES white.
        {"ACES2065-1",
         "lin_ap0_scene",
         "ACES2065-1 (AP0 primaries, ACES white)",
         {0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.0770, 0.32168, 0.33767}},
        // SMPTE EG 432-1:2010 (P3 primaries) with the D65 white of Display P3.
        {"lin_p3d65",
         "lin_p3d65_scene",
         "Display P3 (P3 primaries, D65)",
         {0.680, 0.320, 0.265, 0.690, 0.150, 0.060, 0.3127, 0.3290}},
        // ITU-R BT.2020-2 table 3.
        {"lin_rec2020",
         "lin_rec2020_scene",
         "Rec.2020 (BT.2020 primaries, D65)",
         {0.708, 0.292, 0.170, 0.797, 0.131, 0.046, 0.3127, 0.3290}},
    };
    return spaces;
}

const WorkingSpace* findWorkingSpace(const std::string& name) {
    static const struct {
        const char* alias;
        const char* name;
    } aliases[] = {
        {"acescg", "ACEScg"},          {"ap1", "ACEScg"},          {"aces", "ACES2065-1"},
        {"ap0", "ACES2065-1"},         {"rec709", "lin_rec709"},   {"lin_srgb", "lin_rec709"},
        {"srgb_linear", "lin_rec709"}, {"linear", "lin_rec709"},   {"scene_linear", "lin_rec709"},
        {"p3", "lin_p3d65"},           {"displayp3", "lin_p3d65"}, {"rec2020", "lin_rec2020"}};
    std::string key = name;
    for (const auto& a : aliases)
        if (strcasecmp(name.c_str(), a.alias) == 0) key = a.name;
    for (const WorkingSpace& s : workingSpaces())
        if (strcasecmp(key.c_str(), s.name) == 0 || strcasecmp(key.c_str(), s.interopID) == 0)
            return &s;
    return nullptr;
}

std::string knownWorkingSpaceNames() {
    std::string s;
    for (const WorkingSpace& w : workingSpaces())
        s += (s.empty() ? "" : ", ") + std::string(w.name);
    return s;
}

const WorkingSpace* matchChromaticities(const Chromaticities& c, double tolerance) {
    auto near = [tolerance](double a, double b) { return std::fabs(a - b) <= tolerance; };
    for (const WorkingSpace& s : workingSpaces()) {
        const Chromaticities& k = s.xy;
        if (near(c.rx, k.rx) && near(c.ry, k.ry) && near(c.gx, k.gx) && near(c.gy, k.gy) &&
            near(c.bx, k.bx) && near(c.by, k.by) && near(c.wx, k.wx) && near(c.wy, k.wy))
            return &s;
    }
    return nullptr;
}

std::string chromaticitiesText(const Chromaticities& c) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "R %.6g %.6g, G %.6g %.6g, B %.6g %.6g, W %.6g %.6g", c.rx, c.ry,
                  c.gx, c.gy, c.bx, c.by, c.wx, c.wy);
    return buf;
}

bool rgbToXyz(const Chromaticities& c, std::array<std::array<double, 3>, 3>& m) {
    // SMPTE RP 177-1993 section 3: P holds the primaries' (x/y, 1, z/y) as columns, W the white's
    // XYZ with Y = 1; the scales S = P^-1 W make NPM = P diag(S).
    const double xy[4][2] = {{c.rx, c.ry}, {c.gx, c.gy}, {c.bx, c.by}, {c.wx, c.wy}};
    double P[3][3], W[3];
    for (int i = 0; i < 4; ++i) {
        const double x = xy[i][0], y = xy[i][1];
        if (!std::isfinite(x) || !std::isfinite(y) || y == 0.0) return false;
        const double X = x / y, Z = (1.0 - x - y) / y;
        if (i < 3) {
            P[0][i] = X;
            P[1][i] = 1.0;
            P[2][i] = Z;
        } else {
            W[0] = X;
            W[1] = 1.0;
            W[2] = Z;
        }
    }
    // P^-1 W by Cramer's rule.
    const double det = P[0][0] * (P[1][1] * P[2][2] - P[1][2] * P[2][1]) -
                       P[0][1] * (P[1][0] * P[2][2] - P[1][2] * P[2][0]) +
                       P[0][2] * (P[1][0] * P[2][1] - P[1][1] * P[2][0]);
    if (!std::isfinite(det) || std::fabs(det) < 1e-12) return false;
    double S[3];
    for (int k = 0; k < 3; ++k) {
        double A[3][3];
        for (int r = 0; r < 3; ++r)
            for (int col = 0; col < 3; ++col) A[r][col] = col == k ? W[r] : P[r][col];
        S[k] = (A[0][0] * (A[1][1] * A[2][2] - A[1][2] * A[2][1]) -
                A[0][1] * (A[1][0] * A[2][2] - A[1][2] * A[2][0]) +
                A[0][2] * (A[1][0] * A[2][1] - A[1][1] * A[2][0])) /
               det;
    }
    for (int r = 0; r < 3; ++r)
        for (int col = 0; col < 3; ++col) m[size_t(r)][size_t(col)] = P[r][col] * S[col];
    return true;
}

namespace {

using M3 = std::array<std::array<double, 3>, 3>;

M3 mul(const M3& a, const M3& b) {
    M3 r{};
    for (size_t i = 0; i < 3; ++i)
        for (size_t j = 0; j < 3; ++j)
            for (size_t k = 0; k < 3; ++k) r[i][j] += a[i][k] * b[k][j];
    return r;
}

bool invert(const M3& a, M3& r) {
    const double det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) -
                       a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
                       a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    if (!std::isfinite(det) || std::fabs(det) < 1e-12) return false;
    for (size_t i = 0; i < 3; ++i)
        for (size_t j = 0; j < 3; ++j) {
            // cofactor of (j, i) over the determinant
            const size_t r0 = (j + 1) % 3, r1 = (j + 2) % 3, c0 = (i + 1) % 3, c1 = (i + 2) % 3;
            r[i][j] = (a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0]) / det;
        }
    return true;
}

}  // namespace

bool rgbToRgb(const Chromaticities& from, const Chromaticities& to, M3& m) {
    M3 a{}, b{}, bInv{};
    if (!rgbToXyz(from, a) || !rgbToXyz(to, b) || !invert(b, bInv)) return false;
    M3 cat{{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
    if (from.wx != to.wx || from.wy != to.wy) {
        // Bradford cone response (Lam 1985; as in the ACES reference configs).
        const M3 B{
            {{0.8951, 0.2664, -0.1614}, {-0.7502, 1.7135, 0.0367}, {0.0389, -0.0685, 1.0296}}};
        M3 BInv{};
        if (!invert(B, BInv)) return false;
        const double ws[3] = {from.wx / from.wy, 1.0, (1.0 - from.wx - from.wy) / from.wy};
        const double wd[3] = {to.wx / to.wy, 1.0, (1.0 - to.wx - to.wy) / to.wy};
        M3 d{};
        for (size_t i = 0; i < 3; ++i) {
            double ls = 0, ld = 0;
            for (size_t k = 0; k < 3; ++k) {
                ls += B[i][k] * ws[k];
                ld += B[i][k] * wd[k];
            }
            d[i][i] = ld / ls;
        }
        cat = mul(BInv, mul(d, B));
    }
    m = mul(bInv, mul(cat, a));
    return true;
}

bool lumaFromChromaticities(const Chromaticities& c, std::array<double, 3>& luma) {
    std::array<std::array<double, 3>, 3> m{};
    if (!rgbToXyz(c, m)) return false;
    luma = m[1];
    return true;
}

}  // namespace mcstat
