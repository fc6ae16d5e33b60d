// A folder that mcstat writes a report into (`--compare:html=DIR`, mcstat.testing's report
// folders; docs/compare.md, "Report folders: what mcstat writes, and what it never touches").
// mcstat never overwrites or deletes a file it did not write: each file it writes into a report
// folder is listed, with its SHA-1, in the folder's manifest `.mcstat-report`, and a later report
// may replace only a listed file whose content still has that hash. Any other file of the folder
// (a user's notes, a test's own renders) is left as it is; a report that would have to replace
// one is refused with one line naming the folder and the file.
#pragma once

#include <string>
#include <vector>

namespace mcstat {

/// The manifest's name inside a report folder. Its content is JSON:
///   {"mcstat_report": 1, "name": "<the report's name>", "files": {"<file>": "<sha1 hex>", ...}}
/// A hash of "" marks a file being written (claimed, not yet sealed).
inline constexpr const char* kReportManifest = ".mcstat-report";

/// Prepares `dir` to receive the files `names` (plain names, no '/'): creates the folder when
/// absent, and checks that none of `names` exists there unless the manifest lists it with the
/// hash its content has (or as being written). Then records `names` in the manifest as being
/// written (so a write cut short leaves files a rerun may replace). False with a one-line `err`
/// naming the folder and the first file it would have overwritten.
bool claimReportFiles(const std::string& dir, const std::vector<std::string>& names,
                      const std::string& name, std::string& err);

/// Records the SHA-1 of each of `names` (written into `dir` since claimReportFiles) in the
/// manifest, written to a temporary name and renamed. False with a one-line `err`.
bool sealReportFiles(const std::string& dir, const std::vector<std::string>& names,
                     const std::string& name, std::string& err);

/// The SHA-1 of a file's bytes as 40 hex digits; empty when it cannot be read.
std::string fileSha1(const std::string& path);

}  // namespace mcstat
