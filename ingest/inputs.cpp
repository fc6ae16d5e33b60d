// The names an ingest is given (ingest.h): a file, a comma-separated list or a glob, in natural
// order; and the one-frame rule over the files they name.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/strutil.h>
#include <fmt/format.h>
#include <glob.h>

#include <algorithm>
#include <cstring>
#include <set>
#include <string>
#include <vector>

#include "ingest_plan.h"
#include "mcstat/ingest/ingest.h"

namespace mcstat {

using namespace ingest_detail;
using OIIO::ImageInput;
using OIIO::ImageSpec;
using OIIO::TypeDesc;

namespace {

bool hasGlobChars(const std::string& s) { return s.find_first_of("*?[") != std::string::npos; }

/// Natural order: "s2.exr" before "s10.exr" (glibc's strverscmp).
bool naturalLess(const std::string& a, const std::string& b) {
    return strverscmp(a.c_str(), b.c_str()) < 0;
}

}  // namespace

bool expandInputs(const std::string& pattern, std::vector<std::string>& paths, std::string& err) {
    std::vector<std::string> items;
    if (OIIO::Filesystem::is_regular(pattern))
        items.push_back(pattern);
    else
        items = OIIO::Strutil::splits(pattern, ",");
    std::vector<std::string> out;
    for (const std::string& raw : items) {
        const std::string item = std::string(OIIO::Strutil::strip(raw));
        if (item.empty()) {
            err = fmt::format("'{}': an empty file name in the list", pattern);
            return false;
        }
        if (!hasGlobChars(item) || OIIO::Filesystem::exists(item)) {
            out.push_back(item);  // checked when opened: "no such file"
            continue;
        }
        glob_t g{};
        const int rv = glob(item.c_str(), GLOB_ERR, nullptr, &g);
        if (rv == GLOB_NOMATCH) {
            globfree(&g);
            err = fmt::format("'{}' matches no file", item);
            return false;
        }
        if (rv != 0) {
            globfree(&g);
            err = fmt::format("'{}': cannot list the files it names ({})", item,
                              rv == GLOB_ABORTED ? "a directory cannot be read" : "out of memory");
            return false;
        }
        for (size_t i = 0; i < g.gl_pathc; ++i) out.push_back(g.gl_pathv[i]);
        globfree(&g);
    }
    std::sort(out.begin(), out.end(), naturalLess);
    for (size_t i = 1; i < out.size(); ++i)
        if (out[i] == out[i - 1]) {
            err = fmt::format("{}: named twice (its samples would count twice)", out[i]);
            return false;
        }
    paths = std::move(out);
    return true;
}

namespace ingest_detail {

/// The frame a render belongs to, by its name (`name.0042.exr`: the number between the last two
/// dots) and by its metadata (Blender's `Frame`, a `frame` attribute); -1 in `name` / `meta` when
/// it does not say.
void frameOf(const InputFile& f, long long& name, long long& meta) {
    name = meta = -1;
    // The text between the last two dots, when it is a whole integer.
    const std::string file = OIIO::Filesystem::filename(f.path);
    const size_t last = file.rfind('.');
    const size_t before =
        last == std::string::npos || last == 0 ? std::string::npos : file.rfind('.', last - 1);
    if (before != std::string::npos) {
        const std::string digits = file.substr(before + 1, last - before - 1);
        int64_t v = 0;
        if (parseIntegerText(digits, v)) name = v;
    }
    for (const char* key : {"Frame", "frame"}) {
        const OIIO::ParamValue* p = f.spec.find_attribute(key);
        if (!p) continue;
        const std::string text = p->get_string();
        char* end = nullptr;
        const long long v = std::strtoll(text.c_str(), &end, 10);
        if (end != text.c_str() && *end == '\0') meta = v;
    }
}

/// Renders of one image are one frame: a glob that matched several frames (by name or by
/// metadata) would merge them into one image. Refused, naming the frames found.
bool checkOneFrame(const Ingest& s, std::string& err) {
    std::set<long long> byName, byMeta;
    for (const InputFile& f : s.files) {
        long long name = -1, meta = -1;
        frameOf(f, name, meta);
        if (name >= 0) byName.insert(name);
        if (meta >= 0) byMeta.insert(meta);
    }
    for (const auto& [frames, how] :
         {std::pair(&byName, "by their names"), std::pair(&byMeta, "by their Frame metadata")}) {
        if (frames->size() < 2) continue;
        std::vector<std::string> list;
        for (long long v : *frames) list.push_back(std::to_string(v));
        err = fmt::format(
            "the {} files are renders of {} frames ({}: {}), not of one image: "
            "ingest each frame by itself, e.g. --ingest 'shot_s*.#.exr' -o "
            "'shot.#.mcstat' (docs/ingest.md)",
            s.files.size(), frames->size(), how, fmt::join(list, ", "));
        return false;
    }
    return true;
}

}  // namespace ingest_detail

}  // namespace mcstat
