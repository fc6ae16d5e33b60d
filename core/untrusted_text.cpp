#include "mcstat/core/untrusted_text.h"

#include <cstdint>
#include <cstdio>

namespace mcstat {

namespace {

/// Length of the valid UTF-8 sequence starting at s[i] (1..4) and its code point, or 0 when the
/// bytes there are not one (RFC 3629: no overlong forms, no surrogates, nothing past U+10FFFF).
size_t decodeUtf8(std::string_view s, size_t i, uint32_t& cp) {
    const auto byte = [&](size_t k) { return static_cast<unsigned char>(s[k]); };
    const unsigned char b0 = byte(i);
    if (b0 < 0x80) {
        cp = b0;
        return 1;
    }
    size_t n;
    uint32_t min;
    if (b0 >= 0xc2 && b0 <= 0xdf) {
        n = 2, min = 0x80, cp = b0 & 0x1f;
    } else if (b0 >= 0xe0 && b0 <= 0xef) {
        n = 3, min = 0x800, cp = b0 & 0x0f;
    } else if (b0 >= 0xf0 && b0 <= 0xf4) {
        n = 4, min = 0x10000, cp = b0 & 0x07;
    } else {
        return 0;  // a continuation byte, 0xc0/0xc1 (always overlong) or 0xf5..0xff
    }
    if (i + n > s.size()) return 0;
    for (size_t k = 1; k < n; ++k) {
        const unsigned char b = byte(i + k);
        if ((b & 0xc0) != 0x80) return 0;
        cp = (cp << 6) | (b & 0x3f);
    }
    if (cp < min || cp > 0x10ffff || (cp >= 0xd800 && cp <= 0xdfff)) return 0;
    return n;
}

/// Code points past ASCII that change how a line reads: C1 controls, the Unicode line and
/// paragraph separators, and the bidirectional formatting characters.
bool hiddenControl(uint32_t cp) {
    return (cp >= 0x80 && cp <= 0x9f) || cp == 0x2028 || cp == 0x2029 || cp == 0x061c ||
           cp == 0x200e || cp == 0x200f || (cp >= 0x202a && cp <= 0x202e) ||
           (cp >= 0x2066 && cp <= 0x2069);
}

void appendHex(std::string& out, unsigned byte) {
    char buf[8];
    std::snprintf(buf, sizeof buf, "\\x%02x", byte & 0xffu);
    out += buf;
}

/// printable() and oneLine(): `s` with its escapes, appended to `out`.
void escapeInto(std::string& out, std::string_view s, bool escapeBackslash) {
    for (size_t i = 0; i < s.size();) {
        const unsigned char b = static_cast<unsigned char>(s[i]);
        if (b >= 0x20 && b < 0x7f) {
            if (b == '\\' && escapeBackslash)
                out += "\\\\";
            else
                out += char(b);
            ++i;
            continue;
        }
        if (b < 0x80) {
            switch (b) {
                case '\n':
                    out += "\\n";
                    break;
                case '\r':
                    out += "\\r";
                    break;
                case '\t':
                    out += "\\t";
                    break;
                default:
                    appendHex(out, b);
            }
            ++i;
            continue;
        }
        uint32_t cp = 0;
        const size_t n = decodeUtf8(s, i, cp);
        if (n == 0) {
            appendHex(out, b);
            ++i;
        } else if (hiddenControl(cp)) {
            char buf[16];
            std::snprintf(buf, sizeof buf, "\\u{%04x}", unsigned(cp));
            out += buf;
            i += n;
        } else {
            out.append(s.data() + i, n);
            i += n;
        }
    }
}

}  // namespace

std::string printable(std::string_view text, size_t maxBytes) {
    size_t end = text.size();
    if (maxBytes > 0 && end > maxBytes) {
        // Cut at a character boundary: when the cut would split a valid sequence, cut before its
        // lead byte (at most three bytes back), so a valid name never shows a broken tail.
        end = maxBytes;
        for (size_t lead = maxBytes; lead + 3 >= maxBytes && lead > 0; --lead) {
            uint32_t cp = 0;
            const size_t n = decodeUtf8(text, lead - 1, cp);
            if (n > 0) {
                if (lead - 1 + n > maxBytes) end = lead - 1;
                break;
            }
        }
    }
    std::string out;
    out.reserve(end + 16);
    escapeInto(out, text.substr(0, end), true);
    if (end < text.size()) {
        const size_t cut = text.size() - end;
        out += "... (" + std::to_string(cut) + (cut == 1 ? " more byte)" : " more bytes)");
    }
    return out;
}

std::string printableList(const std::vector<std::string>& names, size_t maxItems) {
    if (names.empty()) return "none";
    std::string out;
    for (size_t i = 0; i < names.size() && i < maxItems; ++i)
        out += (i ? ", '" : "'") + printable(names[i]) + "'";
    if (names.size() > maxItems) out += ", ... (" + std::to_string(names.size()) + " in all)";
    return out;
}

std::string oneLine(std::string_view message) {
    std::string out;
    out.reserve(message.size());
    escapeInto(out, message, false);
    return out;
}

std::string libraryMessage(std::string_view text) {
    std::string s(text);
    for (char& c : s)
        if (c == '\n' || c == '\r') c = ' ';
    const size_t first = s.find_first_not_of(' ');
    if (first == std::string::npos) return std::string();
    return oneLine(std::string_view(s).substr(first, s.find_last_not_of(' ') - first + 1));
}

bool isPrintable(std::string_view text, bool newlineSeparators) {
    for (size_t i = 0; i < text.size();) {
        const unsigned char b = static_cast<unsigned char>(text[i]);
        if ((b >= 0x20 && b < 0x7f) || (b == '\n' && newlineSeparators)) {
            ++i;
            continue;
        }
        uint32_t cp = 0;
        const size_t n = b < 0x80 ? 0 : decodeUtf8(text, i, cp);
        if (n == 0 || hiddenControl(cp)) return false;
        i += n;
    }
    return true;
}

}  // namespace mcstat
