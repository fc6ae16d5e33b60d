// Report folders that never lose a user's file (include/mcstat/compare/report/report_folder.h).
#include "mcstat/compare/report/report_folder.h"

#include <OpenImageIO/hash.h>
#include <fmt/format.h>

#include <cctype>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <nlohmann/json.hpp>

#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/codec/temp_file.h"

namespace mcstat {

namespace fs = std::filesystem;

namespace {

/// The files the manifest of `dir` lists, name -> SHA-1 ("" while being written). A missing or
/// unreadable manifest lists nothing: then every existing file of the folder is the user's.
std::map<std::string, std::string> listedFiles(const fs::path& dir) {
    std::map<std::string, std::string> files;
    std::ifstream f(dir / kReportManifest, std::ios::binary);
    if (!f) return files;
    const nlohmann::json j = nlohmann::json::parse(f, nullptr, /*allow_exceptions=*/false);
    if (!j.is_object() || j.value("mcstat_report", 0) != 1 || !j.contains("files") ||
        !j["files"].is_object())
        return files;
    for (const auto& [file, hash] : j["files"].items())
        if (hash.is_string()) {
            std::string hex = hash.get<std::string>();
            for (char& c : hex) c = char(std::tolower(static_cast<unsigned char>(c)));
            files[file] = hex;
        }
    return files;
}

bool writeManifest(const fs::path& dir, const std::string& name,
                   const std::map<std::string, std::string>& files, std::string& err) {
    nlohmann::json j;
    j["mcstat_report"] = 1;
    j["name"] = oneLine(name);
    j["files"] = nlohmann::json::object();
    for (const auto& [file, hash] : files) j["files"][file] = hash;
    return writeTextAtomically((dir / kReportManifest).string(), j.dump(1) + "\n", err);
}

}  // namespace

std::string fileSha1(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    if (!f) return {};
    const std::string bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    if (f.bad()) return {};
    std::string hex = OIIO::SHA1::digest(bytes.data(), bytes.size());
    for (char& c : hex) c = char(std::tolower(static_cast<unsigned char>(c)));  // as sha1sum
    return hex;
}

bool claimReportFiles(const std::string& dirName, const std::vector<std::string>& names,
                      const std::string& name, std::string& err) {
    const fs::path dir(dirName);
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec || !fs::is_directory(dir)) {
        err = fmt::format("{}: cannot create the report's folder ({})", oneLine(dirName),
                          ec ? ec.message() : "not a folder");
        return false;
    }
    std::map<std::string, std::string> listed = listedFiles(dir);
    for (const std::string& file : names) {
        const fs::file_status st = fs::symlink_status(dir / file, ec);
        if (ec || st.type() == fs::file_type::not_found) continue;
        const auto it = listed.find(file);
        const bool ours = it != listed.end() && st.type() == fs::file_type::regular &&
                          (it->second.empty() || it->second == fileSha1((dir / file).string()));
        if (!ours) {
            err = fmt::format(
                "{}: holds {}, which mcstat did not write (a report goes into a folder of its "
                "own: name a new or empty folder)",
                oneLine(dirName), oneLine(file));
            return false;
        }
    }
    for (const std::string& file : names) listed[file] = "";
    return writeManifest(dir, name, listed, err);
}

bool sealReportFiles(const std::string& dirName, const std::vector<std::string>& names,
                     const std::string& name, std::string& err) {
    const fs::path dir(dirName);
    std::map<std::string, std::string> listed = listedFiles(dir);
    for (const std::string& file : names) {
        listed[file] = fileSha1((dir / file).string());
        if (listed[file].empty()) {
            err = fmt::format("{}: cannot read back {}", oneLine(dirName), oneLine(file));
            return false;
        }
    }
    return writeManifest(dir, name, listed, err);
}

}  // namespace mcstat
