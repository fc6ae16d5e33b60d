// gnuplot for the tool's pictures (--qualityplot, --tradeplot): whether it is there, running it on
// a script in a temporary directory, and text safe inside a gnuplot title.
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <string>
#include <utility>
#include <vector>

namespace mcstat::cli {

/// Whether an executable "gnuplot" is on $PATH, so a command can refuse before computing anything.
bool haveGnuplot(std::string& err);

/// Runs gnuplot on `script` in a temporary directory holding `dataFiles` (name, content); the
/// script writes the PNG `pngName` (a plain name in that directory), which is returned in `out` as
/// RGB float. False with a one-line `err` when gnuplot is missing, fails or writes no image.
bool runGnuplot(const std::string& script,
                const std::vector<std::pair<std::string, std::string>>& dataFiles,
                const std::string& pngName, OIIO::ImageBuf& out, std::string& err);

/// Keeps only characters that mean nothing to gnuplot inside a single-quoted string (no quotes,
/// backquotes, backslashes, '@' or '&'), so a file or method name can go into a title safely.
std::string plotSafe(const std::string& s);

}  // namespace mcstat::cli
