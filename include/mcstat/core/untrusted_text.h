// Strings an input file supplies, made safe to print. A channel, part, layer or attribute name, an
// attribute's text, a Cryptomatte manifest or a scene-file string is untrusted: a crafted file can
// put a newline into it (a one-line error becomes two, and the second can forge a verdict), or an
// escape sequence (ESC [ ...) that recolours a terminal, rewrites earlier lines or sets a window
// title. Every message, --info line, -v listing, caption and attribute mcstat writes that carries
// such a string shows it through printable(); every sink of one-line messages (the CLI's errors,
// warnings and notes, the plugin's errors) passes the whole line through oneLine() as well, so a
// string that missed printable() still cannot break the line. docs/untrusted.md has the rules.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace mcstat {

/// Bytes of one untrusted string shown before it is cut: a long channel name stays whole, a 1 MB
/// attribute does not flood a log.
inline constexpr size_t kShownBytes = 200;

/// An untrusted string for a message. Printable ASCII and valid UTF-8 of printable characters
/// stay as they are; everything a terminal or a reader could take for something else becomes a
/// visible escape:
///   - the C0 controls, DEL and the backslash itself: \n \r \t \\ and \xNN for the others (ESC is
///     \x1b), so an escaped string reads back unambiguously;
///   - bytes that are not valid UTF-8 (stray continuation bytes, overlong forms, surrogates, code
///     points past U+10FFFF, a sequence cut short): \xNN per byte;
///   - the C1 controls U+0080..U+009F (U+009B is a one-character CSI to some terminals), the line
///     and paragraph separators U+2028/U+2029 and the bidirectional controls (U+061C, U+200E/F,
///     U+202A..U+202E, U+2066..U+2069, which reorder what a reader sees): \u{XXXX}.
/// A string longer than `maxBytes` bytes is cut at a character boundary at or before maxBytes
/// and ends with "... (N more bytes)", N counted in the input (so the cut never splits a
/// character). maxBytes = 0: never cut.
std::string printable(std::string_view text, size_t maxBytes = kShownBytes);

/// Names for a message, each printable() and quoted, comma-separated: "'R', 'G', 'B'"; past
/// `maxItems` names, ", ... (N in all)". "none" for an empty list.
std::string printableList(const std::vector<std::string>& names, size_t maxItems = 16);

/// A whole message for one line of output: printable()'s escapes, except that the backslash stays
/// as it is (the message may already hold printable()'s escapes) and nothing is cut. The sinks'
/// backstop.
std::string oneLine(std::string_view message);

/// A library's message (OIIO's geterror(), an OpenEXR exception's what()) for one line of ours:
/// its line breaks become spaces, leading and trailing spaces go, then oneLine()'s escapes (such a
/// message may quote a file's names).
std::string libraryMessage(std::string_view text);

/// Whether `text` holds nothing printable() would escape, other than the backslash (newlines
/// allowed between lines when `newlineSeparators`). What tests and fuzz targets assert of output.
bool isPrintable(std::string_view text, bool newlineSeparators = false);

}  // namespace mcstat
