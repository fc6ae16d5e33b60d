// The `mcstat` command line: oiiotool's conventions. Arguments are read left to right; file names
// push images (or statistics files) on a stack, commands operate on the top, `-o FILE` writes it.
// Commands take ":name=value" modifiers, e.g. `--gmon:mode=channel:diag=1`.
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <array>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "mcstat/analysis/metrics.h"
#include "mcstat/compact/compact.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/registry.h"
#include "mcstat/image/spec/render_layout.h"
#include "mcstat/ingest/ingest.h"

namespace mcstat::cli {

/// One stack entry: a statistics file (loaded lazily: pushing reads and checks only its headers) or
/// an ordinary image.
struct Item {
    std::string name;  ///< what messages call it: the file name or "op(input)"
    std::string path;  ///< source file of a statistics item ("" when computed)
    StatsHeader header;
    std::shared_ptr<StatsImage> stats;  ///< null until needed (statistics items)
    /// A merge not computed yet (`--merge`, one node of its tree): read block by block from these
    /// items, merged in this order, when used.
    std::vector<std::shared_ptr<const Item>> mergeInputs;
    /// A compact file not computed yet (`--compact`): this item's rows, compacted by
    /// `compactRule` block by block when used.
    std::shared_ptr<const Item> compactInput;
    CompactRule compactRule;
    /// Renders not read yet (`--ingest`): their headers, read block by block when used.
    std::shared_ptr<const IngestSource> ingest;
    std::vector<std::string> files;  ///< the renders an --ingest reads (for --compare's reports)
    std::shared_ptr<OIIO::ImageBuf> image;  ///< set for image items
    /// An image computed from a statistics file: that file's header, so that -o writes the result
    /// laid out as the input render was (names, parts, AOVs; render_layout.h). Null otherwise.
    std::shared_ptr<const StatsHeader> layout;
    bool isStats() const { return image == nullptr; }
};

using Modifiers = std::map<std::string, std::string>;

// A command reads its modifiers back with core's modifierValue / modifierList (core/params.h),
// through the specs of its Command::modifiers.

struct State {
    std::vector<Item> stack;
    int nthreads = 0;  ///< 0: all cores
    bool verbose = false;
    /// The process's exit status once every command has run: 2 when a --compare found the two
    /// renders different (idiff's FAILURE), else 0. Errors stop the run with 1 at once.
    int exitStatus = 0;
    /// Image encoding of every later -o (-d, --compression); writeOptionsSet once either is given.
    ImageWriteOptions write;
    bool writeOptionsSet = false;
    bool noClobber = false;  ///< --no-clobber: -o keeps an existing file
};

struct Command {
    std::string name;  ///< with dashes, e.g. "--gmon"
    int nargs = 0;
    std::string argHelp;  ///< e.g. "FILE"
    std::string help;     ///< one line
    /// The modifiers it accepts, typed: checked by the one parser (parseParamValue) before the
    /// command runs, their defaults filled in, and --help generated from them.
    std::vector<ParamSpec> modifiers;
    bool (*run)(State&, const std::string& cmd, const std::vector<std::string>& args,
                const Modifiers& mods, std::string& err) = nullptr;
    std::string operation;  ///< for commands generated from the operation registry
};

/// The modifiers of the metrics (ratio, floor, eps and, with `neps`, neps) and REF's `layer`, as
/// --diff and the review commands declare them.
std::vector<ParamSpec> diffModifiers(bool neps);
/// --ingest's modifiers (io.cpp).
std::vector<ParamSpec> ingestModifiers();
/// -o's modifiers, type and compression (io.cpp).
std::vector<ParamSpec> outputModifiers();

/// The metrics' modifiers of --diff and the review commands (ratio, floor, eps, neps; others are
/// left alone; the command table has checked them) into `opt`, whose luma the caller sets.
void readDiffOptions(const Modifiers& mods, DiffOptions& opt);
/// The one line --diff prints for image `name` (the review commands print the same).
void printDiffLine(const std::string& name, const DiffMetrics& m);

/// Replaces `top` by the image `img` that operation `op` computed from it, named "op(top)". The
/// render layout (Item::layout) follows from a statistics item or an image that had one, when
/// `keepLayout` (a picture made for review has none).
void replaceWithImage(Item& top, const std::string& op, std::shared_ptr<OIIO::ImageBuf> img,
                      bool keepLayout = false);
/// After an operation on the statistics item `top`: its provenance and the source render's
/// metadata on `img` (describeResult), and the warnings a user must hear: an estimator that
/// cannot differ from the plain mean at this M, AOVs an operation does not carry.
void describeOperationResult(const Item& top, const Operation& op, const ParamValues& values,
                             OIIO::ImageBuf& img);

/// -q anywhere on the command line (oiiotool's quiet mode): no warnings, notes or progress lines;
/// errors and what a command prints on stdout (--diff, --compare) remain.
bool quiet();
/// "mcstat: warning: TEXT" / "mcstat: note: TEXT" on stderr, unless quiet().
void warning(const std::string& text);

/// The working space of an item (docs/color.md): a statistics item's mcstat:colorSpace; an
/// image's as ingest reads an input's (colorSpaceOf: colorInteropID, chromaticities,
/// oiio:ColorSpace), lin_rec709 when it names none. False with `err` naming the item when its
/// metadata names a space mcstat cannot place.
bool itemSpace(const Item& item, std::string& space, std::string& err);
/// The same for an image's spec; `what` names it in errors.
bool imageSpace(const OIIO::ImageSpec& spec, const std::string& what, std::string& space,
                std::string& err);
/// Whether `item` is an image read from the file its name names (not a statistics file, not a
/// computed image): one that a printed oiiotool command can convert.
bool isImageFile(const Item& item);
/// Refuses two working spaces that differ, with what to do: "CMD: A is in X but B is in Y: ...",
/// with the stock oiiotool command (no OCIO config needed) that converts B into A's space when
/// `bFile` (B is an image file), else A into B's when `aFile`, else the command for each render
/// of a re-ingest.
bool sameSpace(const std::string& cmd, const std::string& a, const std::string& spaceA,
               const std::string& b, const std::string& spaceB, std::string& err,
               bool aFile = false, bool bFile = false);
/// Prints once per process the note displayNote gives for pixels of working space `space`
/// (shown through a matrix because the config lacks the space), unless quiet().
void noteDisplayRoute(const std::string& space);
/// The luminance weights of `item`'s working space (lumaCoefficients in color.h), any warning
/// printed; false with `err` naming the item when its space is unknown.
bool itemLuma(const Item& item, std::array<double, 3>& luma, std::string& err);
/// The same for working space `space` of the file or image `what` names.
bool spaceLuma(const std::string& space, const std::string& what, std::array<double, 3>& luma,
               std::string& err);
void note(const std::string& text);
/// Whether a progress line belongs on stderr: a terminal, and not quiet().
bool showProgress();

/// Runs a whole command line; returns the process exit code. Errors print one line to stderr.
int run(int argc, const char* const* argv);
/// Runs the arguments (without the program name) once: the process exit code; an error prints
/// one line to stderr, after `context` (e.g. "frame 3: ").
int runOnce(const std::vector<std::string>& args, const std::string& context);
/// --parallel-frames starts each frame as "mcstat --frame-context N ARGS...": the child's errors
/// then say "frame N: " as the serial run's do. Internal; not in --help.
inline constexpr const char* kFrameContextArg = "--frame-context";

// Implemented in frames.cpp: frame sequences (#, @, %0Nd, --frames, --parallel-frames).
/// Whether the arguments hold a frame pattern or a frame option that needs one.
bool hasFramePattern(const std::vector<std::string>& args);
/// Runs the command line once per frame; the exit status: 1 when a frame failed, else 2 when a
/// frame's --compare found a difference, else 0.
int runFrames(const std::vector<std::string>& args);

// Commands implemented in io.cpp.
bool pushFile(State& st, const std::string& path, std::string& err);
/// The block source of a statistics item and everything it reads from (a merge's inputs).
struct ItemSource {
    std::vector<std::unique_ptr<StatsBlockSource>> owned;
    StatsBlockSource* root = nullptr;
};
/// Opens the statistics item `item` as a block source: its file, its image in memory, or the
/// merge of its two inputs. False with `err` on a bad file or an impossible merge.
bool openSource(const State& st, const Item& item, ItemSource& src, std::string& err);
bool loadStats(State& st, Item& item, std::string& err);
/// An ingest item's header with its final seeds (the RGB hashes), reading the renders' RGB once
/// if no pass has yet; any other item as it is.
bool settleIngest(State& st, Item& item, std::string& err);
bool cmdOutput(State&, const std::string&, const std::vector<std::string>&, const Modifiers&,
               std::string&);
bool cmdInfo(State&, const std::string&, const std::vector<std::string>&, const Modifiers&,
             std::string&);
/// --check: checkStatsFile on the top item's file.
bool cmdCheck(State&, const std::string&, const std::vector<std::string>&, const Modifiers&,
              std::string&);
/// --ingest PATTERN: one statistics file from renders of one image (one EXR per seed).
bool cmdIngest(State&, const std::string&, const std::vector<std::string>&, const Modifiers&,
               std::string&);
/// Reads a file as an image: a statistics file gives its beauty (the plain mean).
bool readImage(const std::string& path, OIIO::ImageBuf& out, std::string& err);
/// Reads `path` (an image, or a statistics file's beauty) and returns its R, G, B chosen by channel
/// name, never by position (docs/ingest.md, "Finding the beauty"): `layer` names the layer (e.g.
/// "ViewLayer.Combined"); empty applies the beauty rules (plain R,G,B; Blender's
/// <ViewLayer>.Combined; a beauty AOV such as RGBA). The result has exactly the channels R, G, B.
/// Errors name the file and list the layers found.
bool readRGB(const std::string& path, const std::string& layer, OIIO::ImageBuf& out,
             std::string& err);
/// The R, G, B of an image in memory, chosen by name as readRGB does; `what` names it in errors.
bool selectRGB(const OIIO::ImageBuf& src, const std::string& layer, const std::string& what,
               OIIO::ImageBuf& out, std::string& err);
/// Spec attribute (int 1) marking an image whose pixels are already display-referred (contact
/// sheets, heatmaps, plots): -o writes them as they are, without the OCIO display view.
inline constexpr const char* kDisplayReferredAttr = "mcstat:displayReferred";

// Implemented in compare_command.cpp: the noise-aware comparison (docs/compare.md).
bool cmdCompare(State&, const std::string&, const std::vector<std::string>&, const Modifiers&,
                std::string&);
/// --compare's modifiers: the test, its level and control, what is tested, tiles, tolerances.
const std::vector<ParamSpec>& compareModifiers();

// Implemented in plan.cpp: Jung's error-rate planner (docs/planner.md); needs nothing on the stack.
bool cmdPlan(State&, const std::string&, const std::vector<std::string>&, const Modifiers&,
             std::string&);
/// --compact (cli.cpp): the top statistics file as a compact one, lazily (Item::compactInput).
bool cmdCompact(State&, const std::string&, const std::vector<std::string>&, const Modifiers&,
                std::string&);
std::vector<ParamSpec> compactModifiers();

/// --plan's modifiers, typed as registry parameters (m is a comma-separated list of such values).
const std::vector<ParamSpec>& planParams();

// Implemented in review_command.cpp: pictures for review tools (contact sheet, heatmaps, quality
// plot).
/// Appends the review commands to the command table.
void appendReviewCommands(std::vector<Command>& table);
/// trade_plot.cpp: --tradeplot.
void appendTradeCommands(std::vector<Command>& table);

}  // namespace mcstat::cli
