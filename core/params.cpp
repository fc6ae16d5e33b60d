// Typed parameters and the one checked parser of values (include/mcstat/core/params.h).
#include "mcstat/core/params.h"

#include <OpenImageIO/strutil.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstdlib>

namespace mcstat {

namespace {

std::string numberText(double v, bool integer) {
    if (v == HUGE_VAL) return "inf";
    if (v == -HUGE_VAL) return "-inf";
    char buf[64];
    if (integer)
        std::snprintf(buf, sizeof buf, "%lld", static_cast<long long>(v));
    else
        std::snprintf(buf, sizeof buf, "%g", v);
    return buf;
}

bool inRange(const ParamSpec& s, double v) {
    return (s.minOpen ? v > s.min : v >= s.min) && (s.maxOpen ? v < s.max : v <= s.max);
}

bool parseBoundedInt(const ParamSpec& s, const std::string& text, int64_t& out) {
    int64_t v = 0;
    if (!parseIntegerText(text, v) || !inRange(s, double(v)) || (s.odd && v % 2 == 0)) return false;
    out = v;
    return true;
}

}  // namespace

ParamSpec realParam(const std::string& name, double lo, double hi, bool loOpen,
                    const std::string& def, const std::string& help, bool fixed) {
    ParamSpec p;
    p.name = name;
    p.type = ParamType::Real;
    p.min = lo;
    p.max = hi;
    p.minOpen = loOpen;
    p.defaultValue = def;
    p.help = help;
    p.fixed = fixed;
    return p;
}

ParamSpec intParam(const std::string& name, double lo, double hi, const std::string& def,
                   const std::string& help) {
    ParamSpec p = realParam(name, lo, hi, false, def, help);
    p.type = ParamType::Int;
    return p;
}

ParamSpec flagParam(const std::string& name, const std::string& def, const std::string& help) {
    ParamSpec p = intParam(name, 0, 1, def, help);
    p.type = ParamType::Flag;
    return p;
}

ParamSpec textParam(const std::string& name, const std::string& def, const std::string& help) {
    ParamSpec p;
    p.name = name;
    p.type = ParamType::Text;
    p.defaultValue = def;
    p.help = help;
    return p;
}

ParamSpec enumParam(const std::string& name, std::vector<std::string> choices,
                    const std::string& def, const std::string& help,
                    std::vector<std::pair<std::string, std::string>> aliases) {
    ParamSpec p;
    p.name = name;
    p.type = ParamType::Enum;
    p.defaultValue = def;
    p.choices = std::move(choices);
    p.aliases = std::move(aliases);
    p.help = help;
    return p;
}

// ---- the parser ---------------------------------------------------------------------------------

bool parseIntegerText(const std::string& text, int64_t& out) {
    if (text.empty() || std::isspace(static_cast<unsigned char>(text[0]))) return false;
    char* end = nullptr;
    errno = 0;
    const long long v = std::strtoll(text.c_str(), &end, 10);
    if (*end != '\0' || errno != 0) return false;
    out = int64_t(v);
    return true;
}

bool parseInt(const std::string& text, const std::string& what, int64_t lo, int64_t hi,
              int64_t& out, std::string& err) {
    int64_t v = 0;
    if (!parseIntegerText(text, v)) {
        err = what + ": expected an integer, got '" + text + "'";
        return false;
    }
    if (v < lo || v > hi) {
        err = what + ": must be between " + std::to_string(lo) + " and " + std::to_string(hi) +
              " (got " + std::to_string(v) + ")";
        return false;
    }
    out = v;
    return true;
}

bool parseUnsignedText(const std::string& text, uint64_t& out) {
    if (text.empty() || !std::isdigit(static_cast<unsigned char>(text[0]))) return false;
    char* end = nullptr;
    errno = 0;
    const unsigned long long v = std::strtoull(text.c_str(), &end, 10);
    if (*end != '\0' || errno != 0) return false;
    out = uint64_t(v);
    return true;
}

bool parseRealTriple(const std::string& text, std::array<double, 3>& out) {
    std::vector<double> w;
    for (size_t start = 0; start <= text.size();) {
        const size_t comma = std::min(text.find(',', start), text.size());
        double d = 0.0;
        if (!parseRealText(text.substr(start, comma - start), d)) return false;
        w.push_back(d);
        start = comma + 1;
    }
    if (w.size() != 3) return false;
    out = {w[0], w[1], w[2]};
    return true;
}

bool parseRealText(const std::string& text, double& out) {
    if (text.empty() || std::isspace(static_cast<unsigned char>(text[0]))) return false;
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(text.c_str(), &end);
    if (*end != '\0' || errno != 0 || !std::isfinite(v)) return false;
    out = v;
    return true;
}

std::string describeParam(const ParamSpec& s) {
    switch (s.type) {
        case ParamType::Flag:
            return "0 or 1";
        case ParamType::Text:
            return "text";
        case ParamType::Enum: {
            std::string t;
            for (size_t i = 0; i < s.choices.size(); ++i)
                t += (i == 0                      ? ""
                      : i + 1 == s.choices.size() ? " or "
                                                  : ", ") +
                     ("'" + s.choices[i] + "'");
            return t;
        }
        case ParamType::Size:
            return std::string("KxL with ") + (s.odd ? "odd " : "") + "K, L in [" +
                   numberText(s.min, true) + ", " + numberText(s.max, true) + "] (e.g. " +
                   s.defaultValue + ")";
        case ParamType::Int:
            return std::string(s.odd ? "an odd integer" : "an integer") + " in [" +
                   numberText(s.min, true) + ", " + numberText(s.max, true) + "]";
        case ParamType::Real:
            if (s.max == HUGE_VAL) {
                if (s.min == -HUGE_VAL) return "a finite number";
                return "a finite number " + std::string(s.minOpen ? "> " : ">= ") +
                       numberText(s.min, false);
            }
            return "a number in " + std::string(s.minOpen ? "(" : "[") + numberText(s.min, false) +
                   ", " + numberText(s.max, false) + (s.maxOpen ? ")" : "]");
    }
    return "";
}

namespace {
bool parseOne(const std::string& context, const ParamSpec& s, const std::string& text,
              ParamValue& out, std::string& err) {
    ParamValue v;
    v.type = s.type;
    v.text = text;
    bool ok = false;
    switch (s.type) {
        case ParamType::Text:
            ok = true;
            break;
        case ParamType::Flag:
            if (text == "1" || text == "true" || text == "on")
                v.integer = 1, ok = true;
            else if (text == "0" || text == "false" || text == "off")
                v.integer = 0, ok = true;
            v.real = double(v.integer);
            break;
        case ParamType::Enum:
            for (const std::string& c : s.choices)
                if (text == c) v.text = c, ok = true;
            for (const auto& [alias, choice] : s.aliases)
                if (text == alias) v.text = choice, ok = true;
            break;
        case ParamType::Int:
            ok = parseBoundedInt(s, text, v.integer);
            v.real = double(v.integer);
            break;
        case ParamType::Size: {
            const size_t x = text.find('x');
            if (x == std::string::npos) {
                ok = parseBoundedInt(s, text, v.integer);
                v.integer2 = v.integer;
            } else {
                ok = parseBoundedInt(s, text.substr(0, x), v.integer) &&
                     parseBoundedInt(s, text.substr(x + 1), v.integer2);
            }
            break;
        }
        case ParamType::Real:
            ok = parseRealText(text, v.real) && inRange(s, v.real);
            break;
    }
    if (!ok) {
        err = context + ": " + s.name + " must be " + describeParam(s) + ", not '" + text + "'";
        return false;
    }
    out = std::move(v);
    return true;
}

}  // namespace

bool parseParamList(const std::string& context, const ParamSpec& s, const std::string& text,
                    std::vector<ParamValue>& out, std::string& err) {
    out.clear();
    size_t start = 0;
    do {
        const size_t comma = std::min(text.find(',', start), text.size());
        ParamValue v;
        if (!parseOne(context, s, text.substr(start, comma - start), v, err)) return false;
        out.push_back(std::move(v));
        start = comma + 1;
    } while (start <= text.size());
    return true;
}

bool parseParamValue(const std::string& context, const ParamSpec& s, const std::string& text,
                     ParamValue& out, std::string& err) {
    if (!s.list) return parseOne(context, s, text, out, err);
    // A list: every element a value of the type; the first one's value, the whole text.
    std::vector<ParamValue> all;
    if (!parseParamList(context, s, text, all, err)) return false;
    out = std::move(all.front());
    out.text = text;
    return true;
}

/// At most 2 edits, or a third of the name for long ones: a slip of the keyboard.
std::string nearestName(const std::string& name, const std::vector<std::string>& candidates) {
    // Compared without case and leading dashes: "-gmon" and "--GMON" both mean --gmon, not --mon.
    const auto key = [](const std::string& s) {
        return OIIO::Strutil::lower(s.substr(std::min(s.find_first_not_of('-'), s.size())));
    };
    const std::string k = key(name);
    std::string best;
    size_t bestDistance = std::max<size_t>(2, k.size() / 3) + 1;
    for (const std::string& c : candidates) {
        const size_t d = OIIO::Strutil::edit_distance(k, key(c));
        if (d < bestDistance) {
            bestDistance = d;
            best = c;
        }
    }
    return best;
}

bool parseParamText(const std::string& text, std::map<std::string, std::string>& kv,
                    std::string& problem) {
    kv.clear();
    if (text.empty()) return true;
    std::string last;
    for (const std::string& item : OIIO::Strutil::splits(text, ":")) {
        const size_t eq = item.find('=');
        const unsigned char first = item.empty() ? 0 : static_cast<unsigned char>(item[0]);
        const bool startsKey = std::isalpha(first) || first == '_';
        if (!last.empty() && !startsKey && eq == std::string::npos) {
            kv[last] += ":" + item;  // the value goes on
            continue;
        }
        if (eq == std::string::npos || eq == 0) {
            problem = "'" + item + "' is not name=value";
            return false;
        }
        last = item.substr(0, eq);
        if (kv.count(last)) {
            problem =
                "'" + last + "' given twice ('" + kv[last] + "' and '" + item.substr(eq + 1) + "')";
            return false;
        }
        kv[last] = item.substr(eq + 1);
    }
    return true;
}

bool parseNamedParams(const std::string& text, std::string& name,
                      std::map<std::string, std::string>& kv, std::string& problem) {
    const size_t colon = text.find(':');
    name = text.substr(0, colon);
    kv.clear();
    return colon == std::string::npos || parseParamText(text.substr(colon + 1), kv, problem);
}

std::string paramText(const std::map<std::string, std::string>& kv) {
    std::string out;
    for (const auto& [key, value] : kv) out += (out.empty() ? "" : ":") + key + "=" + value;
    return out;
}

std::string realText(double v) {
    char buf[64];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);  // shortest round trip
    return std::string(buf, r.ptr);
}

ParamValue modifierValue(const std::vector<ParamSpec>& specs,
                         const std::map<std::string, std::string>& mods, const std::string& name) {
    ParamValue v;
    const auto it = mods.find(name);
    if (it == mods.end()) return v;  // no default, not given: unset
    std::string ignored;             // checkModifiers has parsed the same text with the same spec
    for (const ParamSpec& p : specs)
        if (p.name == name) parseParamValue("modifier", p, it->second, v, ignored);
    return v;
}

std::vector<ParamValue> modifierList(const std::vector<ParamSpec>& specs,
                                     const std::map<std::string, std::string>& mods,
                                     const std::string& name) {
    std::vector<ParamValue> v;
    const auto it = mods.find(name);
    if (it == mods.end()) return v;
    std::string ignored;  // as above: already checked
    for (const ParamSpec& p : specs)
        if (p.name == name) parseParamList("modifier", p, it->second, v, ignored);
    return v;
}

bool takeModifiers(const std::string& command, const std::vector<ParamSpec>& specs,
                   std::map<std::string, std::string>& mods, ParamValues& out, std::string& err) {
    for (const ParamSpec& spec : specs) {
        const auto it = mods.find(spec.name);
        if (it == mods.end()) continue;
        if (!parseParamValue(command, spec, it->second, out[spec.name], err)) return false;
        mods.erase(it);
    }
    return true;
}

bool checkModifiers(const std::string& command, const std::vector<ParamSpec>& specs,
                    std::map<std::string, std::string>& mods, std::string& err) {
    for (const auto& [key, text] : mods) {
        const ParamSpec* spec = nullptr;
        for (const ParamSpec& p : specs)
            if (p.name == key && !p.fixed) spec = &p;
        if (spec == nullptr) {
            std::vector<std::string> names;
            for (const ParamSpec& p : specs)
                if (!p.fixed) names.push_back(p.name);
            const std::string near = nearestName(key, names);
            err = command + " has no modifier '" + key + "'" +
                  (near.empty() ? std::string() : " (did you mean " + near + "?)") + " (" +
                  (names.empty() ? std::string("it takes none")
                                 : "accepted: " + OIIO::Strutil::join(names, ", ")) +
                  ")";
            return false;
        }
        ParamValue value;
        if (!parseParamValue(command, *spec, text, value, err)) return false;
    }
    for (const ParamSpec& p : specs)
        if (!p.fixed && !p.defaultValue.empty() && !mods.count(p.name))
            mods[p.name] = p.defaultValue;
    return true;
}

}  // namespace mcstat
