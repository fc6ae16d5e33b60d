// Reports of a noise-aware comparison: JUnit XML, JSON and a review page
// (include/mcstat/compare/report/compare_report.h, docs/compare.md "Reports for CI").
#include "mcstat/compare/report/compare_report.h"

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "mcstat/compare/report/report_folder.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/codec/temp_file.h"
#include "mcstat/review/review_pictures.h"

namespace mcstat {

namespace {

/// A number for JSON: NaN and Inf have no spelling there, null stands for them.
nlohmann::json number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); }

nlohmann::json findingJson(const CompareFinding& f, const CompareResult& r) {
    if (!f.valid) return nullptr;
    nlohmann::json j;
    j["x"] = f.x;
    j["y"] = f.y;
    if (f.tile) j["size"] = r.tile;
    j["quantity"] = oneLine(f.quantity);
    j["a"] = number(f.a);
    j["b"] = number(f.b);
    j["effect"] = number(f.result.difference);
    j["relative_effect"] = f.a != 0.0 ? number(f.result.difference / std::fabs(f.a)) : nullptr;
    j["z"] = number(f.result.z);
    j["exact"] = !std::isfinite(f.result.z) && !std::isnan(f.result.z);  // no noise, a difference
    j["p"] = number(f.result.p);
    return j;
}

nlohmann::json sideJson(const CompareReportSide& s) {
    nlohmann::json files = nlohmann::json::array();
    for (const std::string& f : s.files) files.push_back(oneLine(f));
    return {{"name", oneLine(s.name)}, {"files", files}};
}

std::string testName(const CompareReportRequest& req) {
    return oneLine(req.name.empty() ? req.a.name + " vs " + req.b.name : req.name);
}

std::string ruleTest(const CompareResult& r, const CompareOptions& opt) {
    if (opt.rule == CompareOptions::Rule::Mitsuba) return "mitsuba-z";
    if (r.oneSample) return "one-sample-t";
    return opt.trimmed ? "yuen" : "welch";
}

std::string controlName(const CompareOptions& opt) {
    if (opt.rule == CompareOptions::Rule::Mitsuba) return "sidak";
    if (opt.test == TwoSampleTest::Equivalence) return "intersection-union";
    return opt.control == Multiplicity::FDR    ? "fdr"
           : opt.control == Multiplicity::FWER ? "fwer"
                                               : "none";
}

/// XML text: oneLine()'s printable text (no control character, valid UTF-8) with the five
/// markup characters escaped; `multiline` keeps line breaks.
std::string xml(const std::string& text) {
    std::string out;
    for (char c : text) {
        switch (c) {
            case '&':
                out += "&amp;";
                break;
            case '<':
                out += "&lt;";
                break;
            case '>':
                out += "&gt;";
                break;
            case '"':
                out += "&quot;";
                break;
            case '\'':
                out += "&apos;";
                break;
            default:
                out += c;
        }
    }
    return out;
}

std::string isoTime() {
    const std::time_t t = std::time(nullptr);
    std::tm tm{};
    gmtime_r(&t, &tm);
    char buf[32];
    std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%S", &tm);
    return buf;
}

/// A picture for the page as an 8-bit PNG of its display-referred values (clamped to [0, 1]),
/// written to a temporary name and renamed.
bool writePng(const OIIO::ImageBuf& img, const std::string& path, std::string& err) {
    if (!checkOutputTarget(path, err)) return false;
    TemporaryFile tmp(path, ".png");
    if (!img.write(tmp.path(), OIIO::TypeUInt8, "png")) {
        err = fmt::format("{}: {}", oneLine(path), libraryMessage(img.geterror()));
        return false;
    }
    return tmp.commit(err);
}

/// Region `roi` of `img`'s R, G, B (`roi` in pixels of its data window counted from (0, 0)) as the
/// page shows it: times `gain`, clamped to [0, 1], through the sRGB curve (no view transform),
/// each pixel enlarged to s x s (nearest pixel). False with `err`.
bool displayPicture(OIIO::ImageBuf& dst, const OIIO::ImageBuf& img, OIIO::ROI roi, int s,
                    std::string& err, double gain = 1.0) {
    const int w = roi.width(), h = roi.height();
    std::vector<float> px(size_t(w) * size_t(h) * 3);
    const OIIO::ROI from(img.roi().xbegin + roi.xbegin, img.roi().xbegin + roi.xend,
                         img.roi().ybegin + roi.ybegin, img.roi().ybegin + roi.yend, 0, 1, 0, 3);
    if (!img.get_pixels(from, OIIO::TypeFloat, px.data())) {
        err = libraryMessage(img.geterror());
        return false;
    }
    for (float& v : px) {
        const double x = std::isfinite(v) ? std::clamp(gain * double(v), 0.0, 1.0) : 0.0;
        v = float(x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1.0 / 2.4) - 0.055);
    }
    OIIO::ImageBuf one(OIIO::ImageSpec(w, h, 3, OIIO::TypeFloat));
    one.set_pixels(OIIO::ROI::All(), OIIO::TypeFloat, px.data());
    if (s == 1) {
        dst = std::move(one);
        return true;
    }
    // Resampling without interpolation at an integer factor: every pixel an s x s block.
    dst.reset(OIIO::ImageSpec(w * s, h * s, 3, OIIO::TypeFloat));
    if (!OIIO::ImageBufAlgo::resample(dst, one, /*interpolate=*/false)) {
        err = libraryMessage(dst.geterror());
        return false;
    }
    return true;
}

}  // namespace

CompareReportRequest compareReportRequest(const std::map<std::string, std::string>& kv) {
    CompareReportRequest req;
    auto get = [&](const char* k) {
        const auto it = kv.find(k);
        return it == kv.end() ? std::string() : it->second;
    };
    req.junit = get("junit");
    req.json = get("json");
    req.html = get("html");
    req.name = get("name");
    return req;
}

std::string compareVerdictWord(const CompareResult& r, const CompareOptions& opt) {
    const std::string v = compareVerdict(r, opt);
    return v.substr(0, v.find(':'));
}

std::string compareJson(const CompareResult& r, const CompareOptions& opt,
                        const CompareReportRequest& req) {
    nlohmann::json j;
    j["name"] = testName(req);
    j["verdict"] = compareVerdictWord(r, opt);
    j["verdict_line"] = oneLine(compareVerdict(r, opt));
    j["fail"] = r.fail;
    j["exit_code"] = compareExitCode(r);
    nlohmann::json quantities = nlohmann::json::array();
    for (const std::string& q : r.quantities) quantities.push_back(oneLine(q));
    j["test"] = {{"rule", opt.rule == CompareOptions::Rule::Mitsuba ? "mitsuba" : "mcstat"},
                 {"test", ruleTest(r, opt)},
                 {"control", controlName(opt)},
                 {"level", opt.level},
                 {"equivalence", opt.test == TwoSampleTest::Equivalence},
                 {"tol", opt.tol},
                 {"reltol", opt.reltol},
                 {"quantities", quantities},
                 {"buffers", {{"a", r.Ma}, {"b", r.Mb}}},
                 {"one_sample", r.oneSample}};
    j["pixels"] = {{"total", r.pixels},
                   {"tested", r.pixelsTested},
                   {"differing", r.pixelsRejected},
                   {"threshold", number(r.threshold)}};
    j["tiles"] = {{"size", r.tile},
                  {"total", r.tiles},
                  {"tested", r.tilesTested},
                  {"differing", r.tilesRejected},
                  {"threshold", number(r.tileThreshold)}};
    if (opt.rule == CompareOptions::Rule::Mitsuba)
        j["channel_tests"] = {{"total", r.channelTests},
                              {"passed", r.channelTestsPassed},
                              {"pass_fraction", opt.passFraction},
                              {"variance_floor", opt.varianceFloor}};
    j["power"] = {{"probability", kComparePower},
                  {"tile_relative", number(r.power.tileRelative)},
                  {"tile_absolute", number(r.power.tileAbsolute)},
                  {"pixel_relative", number(r.power.pixelRelative)},
                  {"pixel_absolute", number(r.power.pixelAbsolute)},
                  {"minpower", opt.minPower},
                  {"underpowered", r.underpowered}};
    j["identical"] = r.identical;
    j["strongest_pixel"] = findingJson(r.strongest, r);
    j["strongest_tile"] = findingJson(r.strongestTile, r);
    j["inputs"] = {{"a", sideJson(req.a)}, {"b", sideJson(req.b)}};
    nlohmann::json evidence = nlohmann::json::array();
    for (const std::string& line : compareEvidence(r, opt)) evidence.push_back(oneLine(line));
    j["evidence"] = evidence;
    j["seconds"] = req.seconds;
    return j.dump(2) + "\n";
}

std::string compareJUnit(const CompareResult& r, const CompareOptions& opt,
                         const CompareReportRequest& req) {
    const std::string name = xml(testName(req));
    const std::string verdict = xml(oneLine(compareVerdict(r, opt)));
    const int failures = r.fail ? 1 : 0;
    const std::string time = fmt::format("{:.3f}", req.seconds);
    std::string evidence;
    for (const std::string& line : compareEvidence(r, opt)) evidence += xml(oneLine(line)) + "\n";
    std::string s = "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n";
    s += fmt::format(
        "<testsuites name=\"mcstat compare\" tests=\"1\" failures=\"{}\" errors=\"0\" "
        "time=\"{}\">\n",
        failures, time);
    s += fmt::format(
        "  <testsuite name=\"mcstat.compare\" tests=\"1\" failures=\"{}\" errors=\"0\" "
        "skipped=\"0\" time=\"{}\" timestamp=\"{}\">\n",
        failures, time, isoTime());
    s += "    <properties>\n";
    auto prop = [&](const std::string& k, const std::string& v) {
        s += fmt::format("      <property name=\"{}\" value=\"{}\"/>\n", k, xml(v));
    };
    prop("verdict", compareVerdictWord(r, opt));
    prop("test", ruleTest(r, opt));
    prop("level", fmt::format("{:g}", opt.level));
    prop("pixels.tested", std::to_string(r.pixelsTested));
    prop("pixels.differing", std::to_string(r.pixelsRejected));
    prop("tiles.tested", std::to_string(r.tilesTested));
    prop("tiles.differing", std::to_string(r.tilesRejected));
    auto num = [](double v) { return std::isfinite(v) ? fmt::format("{:.6g}", v) : std::string(); };
    prop("power.probability", fmt::format("{:g}", kComparePower));
    prop("power.tile_relative", num(r.power.tileRelative));
    prop("power.pixel_relative", num(r.power.pixelRelative));
    prop("power.minpower", fmt::format("{:g}", opt.minPower));
    prop("a", oneLine(req.a.name));
    prop("b", oneLine(req.b.name));
    s += "    </properties>\n";
    s += fmt::format("    <testcase classname=\"mcstat.compare\" name=\"{}\" time=\"{}\">\n", name,
                     time);
    if (r.fail)
        s += fmt::format("      <failure message=\"{}\" type=\"{}\">{}{}</failure>\n", verdict,
                         xml(compareVerdictWord(r, opt)), verdict + "\n", evidence);
    s += fmt::format("      <system-out>{}\n{}</system-out>\n", verdict, evidence);
    s += "    </testcase>\n  </testsuite>\n</testsuites>\n";
    return s;
}

namespace {

/// Pictures of the whole image are shown at least this wide, enlarged pixel for pixel.
constexpr int kPageMinWidth = 480;
/// The crop of the strongest region is enlarged to about this width.
constexpr int kCropWidth = 256;
/// The colour of the differing tiles' outlines on A (display-referred): a yellow that no grey,
/// red or green of a render is.
constexpr std::array<float, 3> kOutlineColor{1.f, 0.85f, 0.f};

/// What the page shows and how large: compareHtml and the pictures of writeHtmlReport both follow
/// it, so the page's sizes are the pictures' own.
struct PageLayout {
    int scale = 1;        ///< every picture of the whole image: s x s screen pixels per pixel
    bool tiles = false;   ///< the map is the tiles' (tile.z) and the outlines frame tiles
    std::string channel;  ///< the map's channel: tile.z or z (of the first quantity tested)
    int unit = 1;         ///< the side of what the outlines frame: a tile, or one pixel
    OIIO::ROI crop;       ///< the crop, in pixels of the data window counted from (0, 0)
    int cropScale = 1;    ///< the crop's own enlargement
    /// The crop's own exposure: 1 over its brightest R, G or B of A and B when that is above 1
    /// (a light, a caustic: the PNG would clip it white), else 1.
    double cropGain = 1.0;
    std::string cropWhat;  ///< what the crop shows, for its caption
    int width() const { return crop.width() * cropScale; }
    int height() const { return crop.height() * cropScale; }
};

PageLayout pageLayout(const CompareResult& r, const CompareOptions& opt) {
    PageLayout L;
    L.scale = std::min(16, defaultReviewScale(r.width, kPageMinWidth));
    // The tiles' map, unless there are none, one only (an image smaller than a tile: a map of one
    // colour), or pixels differ where no tile does (a small change: the pixels show it).
    L.tiles = r.tile > 0 && r.tiles >= 2 && !(r.tilesRejected == 0 && r.pixelsRejected > 0);
    L.unit = L.tiles ? r.tile : 1;
    const std::string prefix = L.tiles ? "tile.z" : "z";
    for (const std::string& c : r.maps.spec().channelnames)
        if (c == prefix || c.rfind(prefix + ".", 0) == 0) {
            L.channel = c;
            break;
        }
    // The crop: the strongest tile (compareEvidence's) when the map is the tiles'; otherwise the
    // strongest pixel's neighbourhood, 16 x 16 pixels inside the image.
    const bool equivalence = opt.test == TwoSampleTest::Equivalence;
    const int side = std::max(1, std::min({16, r.width, r.height}));
    const CompareFinding &t = r.strongestTile, &p = r.strongest;
    int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
    std::string what;
    if (L.tiles && t.valid) {
        x0 = t.x - r.originX;
        y0 = t.y - r.originY;
        x1 = std::min(x0 + r.tile, r.width);  // a tile at the right or bottom edge is cut
        y1 = std::min(y0 + r.tile, r.height);
        what = equivalence           ? "the least equivalent tile"
               : r.tilesRejected > 0 ? "the strongest tile"
                                     : "the tile of the largest |z|";
    } else {
        const int cx = p.valid ? p.x - r.originX : r.width / 2;
        const int cy = p.valid ? p.y - r.originY : r.height / 2;
        x0 = std::clamp(cx - side / 2, 0, r.width - side);
        y0 = std::clamp(cy - side / 2, 0, r.height - side);
        x1 = x0 + side;
        y1 = y0 + side;
        what = !p.valid ? std::string("the image's centre (no hypothesis tested)")
                        : fmt::format("the neighbourhood of {}, ({}, {})",
                                      equivalence            ? "the least equivalent pixel"
                                      : r.pixelsRejected > 0 ? "the strongest pixel"
                                                             : "the pixel of the largest |z|",
                                      p.x, p.y);
    }
    L.crop = OIIO::ROI(x0, x1, y0, y1);
    L.cropScale = std::clamp(kCropWidth / std::max(L.crop.width(), L.crop.height()), 1, 32);
    float brightest = 0.f;
    for (const OIIO::ImageBuf* mean : {&r.meanA, &r.meanB}) {
        std::vector<float> px(size_t(L.crop.npixels()) * 3);
        const OIIO::ROI& d = mean->roi();
        if (d.width() < r.width || d.height() < r.height || mean->nchannels() < 3) continue;
        mean->get_pixels(
            OIIO::ROI(d.xbegin + x0, d.xbegin + x1, d.ybegin + y0, d.ybegin + y1, 0, 1, 0, 3),
            OIIO::TypeFloat, px.data());
        for (float v : px)
            if (std::isfinite(v)) brightest = std::max(brightest, v);
    }
    if (brightest > 1.f) L.cropGain = 1.0 / double(brightest);
    L.cropWhat = fmt::format("{}: {}x{} pixels from ({}, {})", what, L.crop.width(),
                             L.crop.height(), x0 + r.originX, y0 + r.originY);
    return L;
}

/// The page's script: the A/B flip on hover (and on a click, for touch screens), the exposure of
/// the pictures of A and B, and once every picture has loaded (or failed) body's data-images ("N
/// of M loaded"), data-sizes (each picture's id, shown and own size) and data-ready, for tests and
/// headless browsers; script errors are collected in data-errors (the listener comes first, in
/// the head).
constexpr const char* kPageScript = R"JS(
"use strict";
(function () {
  const flip = document.getElementById("flip");
  const caption = document.getElementById("flip-caption");
  let side = "b";
  function show(s) {
    side = s;
    flip.src = flip.dataset[s];
    caption.textContent = flip.dataset[s + "Caption"];
  }
  flip.addEventListener("mouseenter", function () { show("a"); });
  flip.addEventListener("mouseleave", function () { show("b"); });
  flip.addEventListener("click", function () { show(side === "a" ? "b" : "a"); });
  const exposure = document.getElementById("exposure");
  const stops = document.getElementById("exposure-value");
  function expose() {
    const s = Number(exposure.value);
    // The pictures hold sRGB-encoded values: a gain of 2^(s / 2.2) on them is close to 2^s on
    // the light (a gamma of 2.2); what the PNG clipped at 1 stays clipped.
    const filter = s === 0 ? "" : "brightness(" + Math.pow(2, s / 2.2).toFixed(4) + ")";
    document.querySelectorAll("img.exposed").forEach(function (i) { i.style.filter = filter; });
    stops.textContent = (s > 0 ? "+" : "") + s + " stops";
  }
  exposure.addEventListener("input", expose);
  expose();
  function check() {
    const images = Array.from(document.images);
    const loaded = images.filter(function (i) { return i.complete && i.naturalWidth > 0; });
    document.body.dataset.images = loaded.length + " of " + images.length + " loaded";
    document.body.dataset.sizes = images.map(function (i) {
      return i.id + "=" + i.width + "x" + i.height + "/" + i.naturalWidth + "x" + i.naturalHeight;
    }).join(" ");
    document.body.dataset.ready = "1";
  }
  if (document.readyState === "complete") check(); else window.addEventListener("load", check);
})();
)JS";

constexpr const char* kPageStyle = R"CSS(
body { font-family: sans-serif; background: #1f1f1f; color: #eee; margin: 1.5em; }
.verdict { font-size: 1.1em; padding: 0.5em 0.8em; border-radius: 4px; }
.fail { background: #7a1f1f; } .pass { background: #1f5f2a; }
figure { display: inline-block; margin: 0 1.5em 1em 0; vertical-align: top; }
figure figure { margin: 0 8px 0 0; }
figcaption { max-width: 40em; color: #ccc; margin-top: 0.3em; }
img { display: block; }
img.px { image-rendering: pixelated; }
#flip { cursor: pointer; }
label { color: #ccc; }
pre { white-space: pre-wrap; }
td, th { padding: 2px 10px; text-align: left; } th { color: #aaa; font-weight: normal; }
)CSS";

std::string findingRow(const char* label, const CompareFinding& f, const CompareResult& r) {
    if (!f.valid) return "";
    const std::string where = f.tile
                                  ? fmt::format("tile {}x{} at ({}, {})", r.tile, r.tile, f.x, f.y)
                                  : fmt::format("pixel ({}, {})", f.x, f.y);
    return fmt::format(
        "<tr><th>{}</th><td>{} {}: {:.6g} &rarr; {:.6g} ({:+.4g}), z = {}, p = {:.3g}</td></tr>\n",
        label, where, xml(oneLine(f.quantity)), f.a, f.b, f.result.difference,
        std::isfinite(f.result.z) ? fmt::format("{:+.2f}", f.result.z) : "exact", f.result.p);
}

std::string numbersTable(const CompareResult& r, const CompareOptions& opt) {
    std::string t = "<table id=\"numbers\">\n";
    t += fmt::format("<tr><th>test</th><td>{}, {}, level {:g}</td></tr>\n", ruleTest(r, opt),
                     controlName(opt), opt.level);
    t += fmt::format("<tr><th>pixels</th><td>{} tested of {}, {} differ</td></tr>\n",
                     r.pixelsTested, r.pixels, r.pixelsRejected);
    if (r.tile > 0)
        t += fmt::format("<tr><th>tiles {}x{}</th><td>{} tested of {}, {} differ</td></tr>\n",
                         r.tile, r.tile, r.tilesTested, r.tiles, r.tilesRejected);
    t += findingRow("strongest pixel", r.strongest, r);
    t += findingRow("strongest tile", r.strongestTile, r);
    return t + "</table>\n";
}

std::string inputsList(const CompareReportRequest& req) {
    std::string s = "<ul>\n";
    for (const auto* side : {&req.a, &req.b}) {
        s += fmt::format("<li>{}: {}", side == &req.a ? "A" : "B", xml(oneLine(side->name)));
        if (!side->files.empty()) {
            std::string files;
            for (const std::string& f : side->files)
                files += (files.empty() ? "" : ", ") + xml(oneLine(f));
            s += fmt::format(" ({} file{}: {})", side->files.size(),
                             side->files.size() == 1 ? "" : "s", files);
        }
        s += "</li>\n";
    }
    return s + "</ul>\n";
}

/// The verdict line and, when it does not state it already (DIFFERENT), what the test could have
/// seen: one line.
std::string verdictWithPower(const CompareResult& r, const CompareOptions& opt) {
    const std::string verdict = compareVerdict(r, opt), power = comparePowerText(r, opt);
    if (power.empty() || verdict.find(power) != std::string::npos) return verdict;
    return verdict + "; " + power;
}

}  // namespace

std::string compareHtml(const CompareResult& r, const CompareOptions& opt,
                        const CompareReportRequest& req) {
    const std::string name = xml(testName(req));
    const std::string a = xml(oneLine(req.a.name)), b = xml(oneLine(req.b.name));
    const PageLayout L = pageLayout(r, opt);
    const int W = r.width * L.scale, H = r.height * L.scale;
    const std::string size = fmt::format("width=\"{}\" height=\"{}\"", W, H);
    // Each figure as wide as its pictures: captions wrap under them, figures sit side by side.
    const std::string figure = fmt::format("<figure style=\"width: {}px\"", W);
    auto shown = [](int k) {
        return k == 1 ? std::string("shown 1:1")
                      : fmt::format("shown at {0}x (one pixel: {0} x {0} screen pixels)", k);
    };
    const std::string scaleText = shown(L.scale);
    std::string s = "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n";
    s += fmt::format("<title>mcstat compare: {}</title>\n<style>{}</style>\n", name, kPageStyle);
    s += "<script>window.addEventListener(\"error\", function (e) { "
         "document.documentElement.dataset.errors = "
         "(document.documentElement.dataset.errors || \"\") + (e.message || \"resource\") + \"; "
         "\"; });</script>\n";
    s += "</head>\n<body>\n";
    s += fmt::format("<h1>{}</h1>\n<p id=\"verdict\" class=\"verdict {}\">{}</p>\n", name,
                     r.fail ? "fail" : "pass", xml(oneLine(verdictWithPower(r, opt))));
    // Where: the map first, A with the differing tiles outlined beside it, at one scale.
    const std::string unit = L.tiles ? fmt::format("{0}x{0} tile", r.tile) : std::string("pixel");
    s += fmt::format(
        "{} id=\"map-figure\"><img id=\"map\" class=\"px\" src=\"heatmap.png\" {} alt=\"{}: "
        "b - a in standard errors per {}\"><img id=\"colorbar\" src=\"colorbar.png\" "
        "alt=\"colour scale\"><figcaption>{}: b &minus; a of each {} in standard errors (warm: B "
        "brighter, cool: B darker); a difference without noise (exact) in the colour of its "
        "end of the scale; {}</figcaption></figure>\n",
        figure, size, xml(L.channel), unit, xml(L.channel), unit, scaleText);
    const size_t differing = L.tiles ? r.tilesRejected : r.pixelsRejected;
    const char* differ = opt.test == TwoSampleTest::Equivalence ? "not shown equivalent" : "differ";
    s += fmt::format(
        "{}><img id=\"outlines\" class=\"px exposed\" src=\"outlines.png\" {} alt=\"A, the "
        "{}s that {} outlined\"><figcaption>A: {}; outlined: {} of {} {}s {}</figcaption>"
        "</figure>\n",
        figure, size, unit, differ, a, differing, L.tiles ? r.tilesTested : r.pixelsTested, unit,
        differ);
    // What: one A/B flip with an exposure control, and the strongest region enlarged.
    s += fmt::format(
        "{}><img id=\"flip\" class=\"px exposed\" src=\"b.png\" {} alt=\"B, A on hover\" "
        "data-a=\"a.png\" data-b=\"b.png\" data-a-caption=\"A: {}\" data-b-caption=\"B: {}\">"
        "<figcaption id=\"flip-caption\">B: {}</figcaption><figcaption>hover or click: A; "
        "{}</figcaption><figcaption><label for=\"exposure\">exposure of A and B</label> <input "
        "type=\"range\" id=\"exposure\" min=\"-6\" max=\"6\" step=\"0.5\" value=\"0\"> <output "
        "id=\"exposure-value\" for=\"exposure\">0 stops</output></figcaption></figure>\n",
        figure, size, a, b, b, scaleText);
    const std::string crop = fmt::format("width=\"{}\" height=\"{}\"", L.width(), L.height());
    s += fmt::format(
        "<figure id=\"crop\" style=\"width: {3}px\"><figure><img id=\"crop-a\" class=\"px "
        "exposed\" src=\"crop-a.png\" "
        "{0} alt=\"A, enlarged\"><figcaption>A</figcaption></figure><figure><img id=\"crop-b\" "
        "class=\"px exposed\" src=\"crop-b.png\" {0} alt=\"B, enlarged\"><figcaption>B"
        "</figcaption></figure><figcaption>{1}, {2}{4}</figcaption></figure>\n",
        crop, xml(L.cropWhat), shown(L.cropScale), 2 * (L.width() + 8),
        L.cropGain < 1.0
            ? fmt::format(", {:+.1f} stops (its brightest pixel white)", std::log2(L.cropGain))
            : std::string());
    s += numbersTable(r, opt);
    s += "<h2>Evidence</h2>\n<pre id=\"evidence\">";
    for (const std::string& line : compareEvidence(r, opt)) s += xml(oneLine(line)) + "\n";
    s += "</pre>\n<h2>Inputs</h2>\n" + inputsList(req);
    s += fmt::format("<script>{}</script>\n</body>\n</html>\n", kPageScript);
    return s;
}

namespace {

/// Frames in kOutlineColor inside each differing tile (each differing pixel, without tiles) of
/// `r` on `pic`, A as the page shows it (L.scale times the image's size). A tile differs when one
/// of its quantities' tile.differs maps is 1.
void drawOutlines(OIIO::ImageBuf& pic, const CompareResult& r, const PageLayout& L) {
    const std::string prefix = L.tiles ? "tile.differs" : "differs";
    std::vector<int> channels;
    const std::vector<std::string>& names = r.maps.spec().channelnames;
    for (size_t c = 0; c < names.size(); ++c)
        if (names[c] == prefix || names[c].rfind(prefix + ".", 0) == 0) channels.push_back(int(c));
    const int s = L.scale, u = L.unit;
    const int t = std::clamp(u * s / 6, 1, 3);  // the frame's width in screen pixels
    for (int y = 0; y < r.height; y += u)
        for (int x = 0; x < r.width; x += u) {
            bool differs = false;
            for (int c : channels)
                differs = differs || r.maps.getchannel(r.originX + x, r.originY + y, 0, c) == 1.f;
            if (!differs) continue;
            const int x0 = x * s, y0 = y * s;
            const int x1 = std::min(x + u, r.width) * s, y1 = std::min(y + u, r.height) * s;
            for (const OIIO::ROI& edge : {OIIO::ROI(x0, x1, y0, std::min(y0 + t, y1)),
                                          OIIO::ROI(x0, x1, std::max(y1 - t, y0), y1),
                                          OIIO::ROI(x0, std::min(x0 + t, x1), y0, y1),
                                          OIIO::ROI(std::max(x1 - t, x0), x1, y0, y1)})
                OIIO::ImageBufAlgo::fill(pic, kOutlineColor, edge);
        }
}

/// The page's pictures, drawn into `dir`: a.png, b.png (the means), heatmap.png (the map) and
/// colorbar.png (its scale), outlines.png (A with the differing tiles framed), all of the whole
/// image at L.scale; crop-a.png and crop-b.png (the strongest region) at L.cropScale.
bool writePictures(const CompareResult& r, const PageLayout& L, const std::filesystem::path& dir,
                   std::string& err, int nthreads) {
    HeatmapOptions hopt;
    hopt.map = "cool-warm";
    hopt.symmetric = true;
    hopt.infiniteAtEnds = true;  // an exact difference is the strongest of its sign
    hopt.channel = L.channel;
    hopt.scale = L.scale;
    hopt.colorBar = false;  // colorbar.png, under it on the page: the map is the image's size
    const std::string folder = oneLine(dir.string());
    OIIO::ImageBuf heat, bar;
    if (!heatmap(heat, r.maps, hopt, {}, nthreads)) {
        err = fmt::format("{}: the map: {}", folder, libraryMessage(heat.geterror()));
        return false;
    }
    int ch = 0;
    ColorScale cs;
    std::string e;
    if (!resolveColorScale(r.maps, hopt, ch, cs, e) ||
        !colorBar(bar, std::max(256, r.width * L.scale), cs)) {
        err = fmt::format("{}: the map's scale: {}", folder,
                          e.empty() ? libraryMessage(bar.geterror()) : e);
        return false;
    }
    const OIIO::ROI all(0, r.width, 0, r.height);
    OIIO::ImageBuf pa, pb, outlines, ca, cb;
    if (!displayPicture(pa, r.meanA, all, L.scale, e) ||
        !displayPicture(pb, r.meanB, all, L.scale, e) ||
        !displayPicture(ca, r.meanA, L.crop, L.cropScale, e, L.cropGain) ||
        !displayPicture(cb, r.meanB, L.crop, L.cropScale, e, L.cropGain) || !outlines.copy(pa)) {
        err = fmt::format("{}: the pictures of A and B: {}", folder,
                          e.empty() ? libraryMessage(outlines.geterror()) : e);
        return false;
    }
    drawOutlines(outlines, r, L);
    const std::pair<const OIIO::ImageBuf*, const char*> files[] = {{&pa, "a.png"},
                                                                   {&pb, "b.png"},
                                                                   {&heat, "heatmap.png"},
                                                                   {&bar, "colorbar.png"},
                                                                   {&outlines, "outlines.png"},
                                                                   {&ca, "crop-a.png"},
                                                                   {&cb, "crop-b.png"}};
    for (const auto& [img, file] : files)
        if (!writePng(*img, (dir / file).string(), err)) return false;
    return true;
}

/// The page's folder: its pictures first, the page last (a page never points at missing ones).
/// The folder may hold other files; a file of the page's names is replaced only when this
/// folder's manifest says mcstat wrote it (report_folder.h): a user's file is never overwritten.
bool writeHtmlReport(const CompareResult& r, const CompareOptions& opt,
                     const CompareReportRequest& req, std::string& err, int nthreads) {
    if (r.meanA.roi().width() <= 0 || r.meanB.roi().width() <= 0 || r.width <= 0 || r.height <= 0) {
        err = fmt::format("{}: the comparison kept no means to show", oneLine(req.html));
        return false;
    }
    const std::vector<std::string> files = {"a.png",        "b.png",        "heatmap.png",
                                            "colorbar.png", "outlines.png", "crop-a.png",
                                            "crop-b.png",   "index.html"};
    if (!claimReportFiles(req.html, files, testName(req), err)) return false;
    const std::filesystem::path dir(req.html);
    const PageLayout L = pageLayout(r, opt);
    return writePictures(r, L, dir, err, nthreads) &&
           writeTextAtomically((dir / "index.html").string(), compareHtml(r, opt, req), err) &&
           sealReportFiles(req.html, files, testName(req), err);
}

}  // namespace

namespace {

/// A report file's folders, created as html=DIR's are (a CI job names out/reports/x.json before
/// anything made out/reports).
bool makeParentFolders(const std::string& file, std::string& err) {
    const std::filesystem::path parent = std::filesystem::path(file).parent_path();
    if (parent.empty()) return true;
    std::error_code ec;
    std::filesystem::create_directories(parent, ec);
    if (ec) {
        err = fmt::format("{}: cannot create its folder ({})", oneLine(file), ec.message());
        return false;
    }
    return true;
}

}  // namespace

bool writeCompareReports(const CompareResult& r, const CompareOptions& opt,
                         const CompareReportRequest& req, std::string& err, int nthreads) {
    if (!req.json.empty() && (!makeParentFolders(req.json, err) ||
                              !writeTextAtomically(req.json, compareJson(r, opt, req), err)))
        return false;
    if (!req.junit.empty() && (!makeParentFolders(req.junit, err) ||
                               !writeTextAtomically(req.junit, compareJUnit(r, opt, req), err)))
        return false;
    if (!req.html.empty() && !writeHtmlReport(r, opt, req, err, nthreads)) return false;
    return true;
}

}  // namespace mcstat
