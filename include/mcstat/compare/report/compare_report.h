// Reports of a noise-aware comparison (`mcstat --compare:junit=FILE:json=FILE:html=DIR`,
// docs/compare.md "Reports for CI"): the verdict and its numbers for CI servers (JUnit XML, as
// Jenkins and GitLab read it), for scripts (JSON) and for a reviewer (a page with the map of
// the tiles' z, the differing tiles outlined on A, an A/B flip and the strongest region
// enlarged). Every file is written to a temporary name and renamed
// (temp_file.h): a report is whole or absent.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "mcstat/compare/compare.h"

namespace mcstat {

/// One side of the comparison as the reports name it.
struct CompareReportSide {
    std::string name;                ///< what the verdict calls it (a path, "ingest(...)")
    std::vector<std::string> files;  ///< the files it was read from (the renders of an ingest)
};

/// What to write, and what the comparison was made of.
struct CompareReportRequest {
    std::string junit, json, html;  ///< a file, a file, a folder; empty: not written
    std::string name;               ///< the test's name (default: "A vs B")
    CompareReportSide a, b;
    double seconds = 0.0;  ///< wall time of the comparison
    /// Whether any report is asked for, and whether the page (which needs both sides' means,
    /// CompareOptions::keepMeans) is.
    bool any() const { return !junit.empty() || !json.empty() || !html.empty(); }
    bool needsMeans() const { return !html.empty(); }
};

/// The reports' parameters (junit, json, html, name) from a --compare's key=value modifiers
/// (compareParams()); the sides and time are the caller's.
CompareReportRequest compareReportRequest(const std::map<std::string, std::string>& kv);

/// The verdict's first word(s): IDENTICAL, SAME, DIFFERENT, EQUIVALENT or NOT SHOWN EQUIVALENT.
std::string compareVerdictWord(const CompareResult& r, const CompareOptions& opt);
/// The process's exit status for it: 0 same, 2 different.
inline int compareExitCode(const CompareResult& r) { return r.fail ? 2 : 0; }

/// The JSON report: verdict, exit code, the test and its level, counts of pixels and tiles
/// tested and differing, the strongest pixel and tile with their effects, the inputs.
std::string compareJson(const CompareResult& r, const CompareOptions& opt,
                        const CompareReportRequest& req);
/// The JUnit XML report: one <testsuites> holding one <testsuite> with one <testcase>, a
/// <failure> when the renders differ, the numbers as <properties>, the evidence in <system-out>.
std::string compareJUnit(const CompareResult& r, const CompareOptions& opt,
                         const CompareReportRequest& req);
/// The page's HTML (docs/compare.md, "Reports for CI"): the verdict with its power in one line,
/// the map (heatmap.png, colorbar.png), A with the differing tiles outlined (outlines.png), the A/B
/// flip (a.png, b.png) with an exposure control and the strongest region enlarged (crop-a.png,
/// crop-b.png), every picture of the whole image at one scale; then the numbers, the evidence and
/// the inputs.
std::string compareHtml(const CompareResult& r, const CompareOptions& opt,
                        const CompareReportRequest& req);

/// Writes every report asked for. The page's folder is created when absent; its pictures are
/// A's and B's means (sRGB curve, clamped), the map of tile.z (or z), its colour scale, A with the
/// differing tiles outlined and the strongest region of A and B enlarged. False with a one-line
/// `err` naming the file.
bool writeCompareReports(const CompareResult& r, const CompareOptions& opt,
                         const CompareReportRequest& req, std::string& err, int nthreads = 0);

}  // namespace mcstat
