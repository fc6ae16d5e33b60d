// Reports of a noise-aware comparison: JUnit XML, JSON and a review page
// (include/mcstat/compare/compare_report.h, docs/compare.md "Reports for CI").
#include "mcstat/compare/compare_report.h"

#include <OpenImageIO/imagebuf.h>
#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "mcstat/compare/report_folder.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/review/review_pictures.h"
#include "mcstat/temp_file.h"

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

/// A picture for the page: a linear image through the sRGB curve, clamped to [0, 1], as 8-bit PNG.
bool writeDisplayPng(const OIIO::ImageBuf& img, const std::string& path, std::string& err,
                     bool linear) {
    OIIO::ImageBuf out(OIIO::ImageSpec(img.roi().width(), img.roi().height(), 3, OIIO::TypeFloat));
    std::vector<float> px(size_t(img.roi().width()) * size_t(img.roi().height()) * 3);
    OIIO::ROI roi = img.roi();
    roi.chbegin = 0;
    roi.chend = 3;
    img.get_pixels(roi, OIIO::TypeFloat, px.data());
    for (float& v : px) {
        double x = std::isfinite(v) ? std::clamp(double(v), 0.0, 1.0) : 0.0;
        if (linear) x = x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1.0 / 2.4) - 0.055;
        v = float(x);
    }
    out.set_pixels(OIIO::ROI::All(), OIIO::TypeFloat, px.data());
    if (!checkOutputTarget(path, err)) return false;
    TemporaryFile tmp(path, ".png");
    if (!out.write(tmp.path(), OIIO::TypeUInt8, "png")) {
        err = fmt::format("{}: {}", oneLine(path), libraryMessage(out.geterror()));
        return false;
    }
    return tmp.commit(err);
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

/// The page's script: the A/B flip on hover, and once every picture has loaded (or failed),
/// body's data-images ("N of M loaded") and data-ready for tests and headless browsers; script
/// errors are collected in data-errors (the listener comes first, in the head).
constexpr const char* kPageScript = R"JS(
"use strict";
(function () {
  const flip = document.getElementById("flip");
  const caption = document.getElementById("flip-caption");
  function show(side) {
    flip.src = flip.dataset[side];
    caption.textContent = flip.dataset[side + "Caption"];
  }
  flip.addEventListener("mouseenter", function () { show("a"); });
  flip.addEventListener("mouseleave", function () { show("b"); });
  function check() {
    const images = Array.from(document.images);
    const loaded = images.filter(function (i) { return i.complete && i.naturalWidth > 0; });
    document.body.dataset.images = loaded.length + " of " + images.length + " loaded";
    document.body.dataset.ready = "1";
  }
  if (document.readyState === "complete") check(); else window.addEventListener("load", check);
})();
)JS";

constexpr const char* kPageStyle = R"CSS(
body { font-family: sans-serif; background: #1f1f1f; color: #eee; margin: 1.5em; }
.verdict { font-size: 1.2em; padding: 0.5em 0.8em; border-radius: 4px; }
.fail { background: #7a1f1f; } .pass { background: #1f5f2a; }
figure { display: inline-block; margin: 0 1.5em 1em 0; vertical-align: top; }
img.px { image-rendering: pixelated; }
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

}  // namespace

std::string compareHtml(const CompareResult& r, const CompareOptions& opt,
                        const CompareReportRequest& req) {
    const std::string name = xml(testName(req));
    const std::string a = xml(oneLine(req.a.name)), b = xml(oneLine(req.b.name));
    // Small renders are shown enlarged, pixel for pixel, to at least 256 pixels wide.
    const int scale = r.width > 0 ? std::max(1, std::min(16, (256 + r.width - 1) / r.width)) : 1;
    const std::string size =
        fmt::format("width=\"{}\" height=\"{}\"", r.width * scale, r.height * scale);
    std::string s = "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n";
    s += fmt::format("<title>mcstat compare: {}</title>\n<style>{}</style>\n", name, kPageStyle);
    s += "<script>window.addEventListener(\"error\", function (e) { "
         "document.documentElement.dataset.errors = "
         "(document.documentElement.dataset.errors || \"\") + (e.message || \"resource\") + \"; "
         "\"; });</script>\n";
    s += "</head>\n<body>\n";
    s += fmt::format("<h1>{}</h1>\n<p id=\"verdict\" class=\"verdict {}\">{}</p>\n", name,
                     r.fail ? "fail" : "pass", xml(oneLine(compareVerdict(r, opt))));
    s += fmt::format(
        "<figure><img id=\"flip\" class=\"px\" src=\"b.png\" {} alt=\"B, A on hover\" "
        "data-a=\"a.png\" data-b=\"b.png\" data-a-caption=\"A: {}\" data-b-caption=\"B: {}\">"
        "<figcaption id=\"flip-caption\">B: {}</figcaption><figcaption>(hover: "
        "A)</figcaption></figure>\n",
        size, a, b, b);
    for (const auto& [side, label] : {std::pair{'a', a}, std::pair{'b', b}})
        s += fmt::format(
            "<figure><img class=\"px\" src=\"{0}.png\" {1} alt=\"{2}\"><figcaption>{2}: "
            "{3}</figcaption></figure>\n",
            side, size, char(std::toupper(side)), label);
    s += "<figure><img src=\"heatmap.png\" alt=\"z, b - a in standard errors\"><figcaption>z: b - "
         "a in "
         "standard errors</figcaption></figure>\n";
    s += numbersTable(r, opt);
    s += "<h2>Evidence</h2>\n<pre id=\"evidence\">";
    for (const std::string& line : compareEvidence(r, opt)) s += xml(oneLine(line)) + "\n";
    s += "</pre>\n<h2>Inputs</h2>\n" + inputsList(req);
    s += fmt::format("<script>{}</script>\n</body>\n</html>\n", kPageScript);
    return s;
}

namespace {

/// The page's folder: its pictures first, the page last (a page never points at missing ones).
/// The folder may hold other files; a file of the page's names is replaced only when this
/// folder's manifest says mcstat wrote it (report_folder.h): a user's file is never overwritten.
bool writeHtmlReport(const CompareResult& r, const CompareOptions& opt,
                     const CompareReportRequest& req, std::string& err, int nthreads) {
    if (r.meanA.roi().width() <= 0 || r.meanB.roi().width() <= 0) {
        err = fmt::format("{}: the comparison kept no means to show", oneLine(req.html));
        return false;
    }
    const std::vector<std::string> files = {"a.png", "b.png", "heatmap.png", "index.html"};
    if (!claimReportFiles(req.html, files, testName(req), err)) return false;
    const std::filesystem::path dir(req.html);
    HeatmapOptions hopt;
    hopt.map = "cool-warm";
    hopt.symmetric = true;
    for (int c = 0; c < r.maps.nchannels(); ++c)
        if (r.maps.spec().channelnames[size_t(c)].rfind("z", 0) == 0) {
            hopt.channel = r.maps.spec().channelnames[size_t(c)];
            break;
        }
    hopt.caption = oneLine(compareVerdictWord(r, opt));
    OIIO::ImageBuf heat;
    if (!heatmap(heat, r.maps, hopt, {}, nthreads)) {
        err =
            fmt::format("{}: the heatmap: {}", oneLine(req.html), libraryMessage(heat.geterror()));
        return false;
    }
    return writeDisplayPng(r.meanA, (dir / "a.png").string(), err, true) &&
           writeDisplayPng(r.meanB, (dir / "b.png").string(), err, true) &&
           writeDisplayPng(heat, (dir / "heatmap.png").string(), err, false) &&
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
