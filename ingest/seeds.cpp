// The seed of each render (ingest.h, docs/ingest.md "Seeds"): what its metadata stamp says (a
// `seed=N` token in the `Note` attribute Blender writes from Output > Metadata > Note, and
// mcstat-blender fills), what its file name says through the user's pattern (--ingest:seed=), the
// two checked against each other; and the rule that two renders of one seed are refused.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/strutil.h>
#include <fmt/format.h>
#include <fnmatch.h>

#include <algorithm>
#include <cctype>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "ingest_plan.h"
#include "mcstat/core/params.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/ingest/ingest.h"

namespace mcstat {

using namespace ingest_detail;

namespace {

constexpr const char* kSeedMark = "{seed}";

bool isDigit(char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; }

/// A run of decimal digits as the seed's canonical text (no leading zeros); false when it does not
/// fit 64 bits.
bool seedValue(const std::string& digits, std::string& out) {
    uint64_t v = 0;
    if (!parseUnsignedText(digits, v)) return false;
    out = std::to_string(v);
    return true;
}

/// The `seed=N` tokens of a note: "seed=" at the start or after a space, comma or semicolon,
/// digits up to the end or to one of those (so `cycles_seed=1001` and `seed=7x` are not one).
/// Case-insensitive key. Every token's digits, in order.
std::vector<std::string> noteSeedTokens(const std::string& note) {
    std::vector<std::string> out;
    const auto boundary = [](char c) {
        return std::isspace(static_cast<unsigned char>(c)) || c == ',' || c == ';';
    };
    for (size_t i = 0; i + 5 < note.size(); ++i) {
        if (i > 0 && !boundary(note[i - 1])) continue;
        if (!OIIO::Strutil::iequals(note.substr(i, 5), "seed=")) continue;
        size_t j = i + 5;
        while (j < note.size() && isDigit(note[j])) ++j;
        if (j == i + 5 || (j < note.size() && !boundary(note[j]))) continue;
        out.push_back(note.substr(i + 5, j - i - 5));
    }
    return out;
}

/// The seed a file's metadata stamp gives: Blender writes the stamp note (Output properties >
/// Metadata > Note, render.stamp_note_text with use_stamp_note) as the string attribute `Note`.
/// "" when it gives none; false when the note names two different seeds or one that does not fit.
bool noteSeed(const InputFile& f, std::string& seed, std::string& err) {
    seed.clear();
    const std::string note = f.spec.get_string_attribute("Note");
    for (const std::string& digits : noteSeedTokens(note)) {
        std::string v;
        if (!seedValue(digits, v)) {
            err = fmt::format("{}: its Note's seed={} does not fit 64 bits", f.path,
                              printable(digits, 40));
            return false;
        }
        if (!seed.empty() && v != seed) {
            err = fmt::format("{}: its Note names two seeds ({} and {}): which one rendered it?",
                              f.path, seed, v);
            return false;
        }
        seed = v;
    }
    return true;
}

/// The last `parts` components of `path` ("a/b/c.exr", 2: "b/c.exr").
std::string lastComponents(const std::string& path, size_t parts) {
    size_t at = path.size();
    for (size_t n = 0; n < parts; ++n) {
        const size_t slash = at == 0 ? std::string::npos : path.rfind('/', at - 1);
        if (slash == std::string::npos) return path;
        at = slash;
    }
    return path.substr(at + 1);
}

}  // namespace

bool checkSeedPattern(const std::string& pattern, std::string& problem) {
    const size_t at = pattern.find(kSeedMark);
    if (at == std::string::npos || pattern.find(kSeedMark, at + 1) != std::string::npos) {
        problem = fmt::format(
            "seed pattern '{}' must hold {{seed}} once, where the file name has the seed's digits "
            "(e.g. seed=shot_s{{seed}}.exr)",
            printable(pattern));
        return false;
    }
    if (!pattern.empty() && pattern[0] == '/') {
        problem = fmt::format(
            "seed pattern '{}' is matched against the end of each path: give it without the "
            "leading '/'",
            printable(pattern));
        return false;
    }
    return true;
}

bool seedFromName(const std::string& path, const std::string& pattern, std::string& seed,
                  std::string& problem) {
    seed.clear();
    const size_t at = pattern.find(kSeedMark);
    const std::string before = pattern.substr(0, at);
    const std::string after = pattern.substr(at + std::char_traits<char>::length(kSeedMark));
    const std::string name =
        lastComponents(path, size_t(std::count(pattern.begin(), pattern.end(), '/')) + 1);
    std::set<std::string> found;
    for (size_t i = 0; i < name.size(); ++i) {
        if (!isDigit(name[i]) || (i > 0 && isDigit(name[i - 1]))) continue;
        size_t j = i;
        while (j < name.size() && isDigit(name[j])) ++j;
        if (fnmatch(before.c_str(), name.substr(0, i).c_str(), FNM_PATHNAME) != 0 ||
            fnmatch(after.c_str(), name.substr(j).c_str(), FNM_PATHNAME) != 0)
            continue;
        std::string v;
        if (!seedValue(name.substr(i, j - i), v)) {
            problem = fmt::format("its name's seed {} does not fit 64 bits",
                                  printable(name.substr(i, j - i), 40));
            return false;
        }
        found.insert(v);
    }
    if (found.empty()) {
        problem = fmt::format(
            "its name '{}' does not match the seed pattern '{}' ({{seed}}: the seed's digits)",
            printable(name), printable(pattern));
        return false;
    }
    if (found.size() > 1) {
        problem = fmt::format(
            "the seed pattern '{}' reads its name '{}' two ways (seeds {}): make the pattern "
            "say where the seed's digits are",
            printable(pattern), printable(name), fmt::join(found, " or "));
        return false;
    }
    seed = *found.begin();
    return true;
}

namespace ingest_detail {

bool seedOf(InputFile& f, const IngestOptions& opt, std::string& err) {
    f.seed.clear();
    f.seedSource.clear();
    std::string fromNote, fromName;
    if (!noteSeed(f, fromNote, err)) return false;
    if (!opt.seedPattern.empty()) {
        std::string problem;
        if (!seedFromName(f.path, opt.seedPattern, fromName, problem)) {
            err = f.path + ": " + problem;
            return false;
        }
    }
    if (!fromNote.empty() && !fromName.empty() && fromNote != fromName) {
        err = fmt::format(
            "{}: its name says seed {} (seed={}) but its Note says seed {}: the file lies about "
            "itself (renamed, or stamped by hand?); fix the name or the note",
            f.path, fromName, printable(opt.seedPattern), fromNote);
        return false;
    }
    if (!fromNote.empty()) {
        f.seed = fromNote;
        f.seedSource = "Note stamp";
    } else if (!fromName.empty()) {
        f.seed = fromName;
        f.seedSource = "name";
    }
    return true;
}

bool checkSeeds(const Ingest& s, std::string& err) {
    std::map<std::string, const InputFile*> seen;
    for (const InputFile& f : s.files) {
        if (f.seed.empty()) continue;
        const auto [it, fresh] = seen.emplace(f.seed, &f);
        if (fresh) continue;
        const InputFile& first = *it->second;
        const std::string by = first.seedSource == f.seedSource
                                   ? "their " + f.seedSource + "s"
                                   : fmt::format("the {} of the first and the {} of the second",
                                                 first.seedSource, f.seedSource);
        err = fmt::format(
            "{} and {} are both renders of seed {} (by {}): renders of one seed share their "
            "samples, so they are not independent; ingest one of them, or render another seed",
            first.path, f.path, f.seed, by);
        return false;
    }
    return true;
}

}  // namespace ingest_detail

}  // namespace mcstat
