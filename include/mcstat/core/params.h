// Typed parameters: what an operation (or a command) accepts, and the one checked parser of
// parameter, modifier and option values. A core type: every layer above declares its parameters
// with it (operations in filters/, the renderer's options), so a value is parsed and
// range-checked in one place, and error messages and --help describe it the same way.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace mcstat {

enum class ParamType {
    Int,   ///< an integer in [min, max] (odd when ParamSpec::odd)
    Real,  ///< a finite number in [min, max] (min excluded when minOpen, max when maxOpen)
    Enum,  ///< one of ParamSpec::choices (or an alias of one)
    Size,  ///< "KxL" or "K" (K x K): integers in [min, max] (odd when ParamSpec::odd)
    Flag,  ///< 0 or 1 (also true/false, on/off)
    Text,  ///< any text (a layer name, a list the command checks itself); empty default: unset
};

struct ParamSpec {
    std::string name;  ///< modifier / configuration key, e.g. "alpha"
    ParamType type = ParamType::Real;
    double min = 0.0, max = 0.0;       ///< Int, Real, Size; +-HUGE_VAL for no bound
    bool minOpen = false;              ///< Real: min itself is excluded
    bool maxOpen = false;              ///< Real: max itself is excluded
    bool odd = false;                  ///< Int, Size: only odd values
    std::string defaultValue;          ///< as text; parses with parseParamValue
    std::vector<std::string> choices;  ///< Enum: the accepted values, the canonical ones
    /// Enum: other spellings, alias -> choice (e.g. "luminance" -> "lum").
    std::vector<std::pair<std::string, std::string>> aliases;
    std::string help;
    /// Fixed by the operation, not a modifier: the value is always defaultValue (e.g. 3DMF's
    /// centre weight 1). Listed so that the operation's whole configuration is in the registry.
    bool fixed = false;
    /// A comma-separated list of such values (e.g. buffer counts "3,5,7"): each is checked.
    bool list = false;
};

/// A parsed parameter value.
struct ParamValue {
    ParamType type = ParamType::Real;
    std::string text;      ///< as given; Enum: the canonical choice
    double real = 0.0;     ///< Real; Int and Flag: the value too
    int64_t integer = 0;   ///< Int, Flag; Size: K (width)
    int64_t integer2 = 0;  ///< Size: L (height)
};

/// Every parameter of one operation, defaults applied: name -> value.
using ParamValues = std::map<std::string, ParamValue>;

/// What `spec` accepts, as error messages and --help say it: "a number in [0, 0.5]", "an integer
/// in [1, 1000000]", "'lum' or 'channel'", "KxL with odd K, L in [1, 255] (e.g. 3x3)", "0 or 1".
std::string describeParam(const ParamSpec& spec);

/// The one checked parser: the whole of `text` must be a value of `spec` in its range. On failure
/// `err` is the one line "<context>: <key> must be <describeParam>, not '<text>'".
bool parseParamValue(const std::string& context, const ParamSpec& spec, const std::string& text,
                     ParamValue& out, std::string& err);
/// The elements of a list parameter's text (ParamSpec::list: comma-separated), each parsed and
/// checked with `spec` as parseParamValue parses one value; false with a one-line `err` naming
/// `context` at the first bad element.
bool parseParamList(const std::string& context, const ParamSpec& spec, const std::string& text,
                    std::vector<ParamValue>& out, std::string& err);

/// The candidate nearest to `name` by edit distance (case and leading dashes ignored: "-gmon" and
/// "--GMON" both mean --gmon), or "" when none is near: for "did you mean" suggestions.
std::string nearestName(const std::string& name, const std::vector<std::string>& candidates);

/// The one check of a command's modifiers (`mcstat --CMD:key=value`, and the keyword arguments of
/// the Python module): each key must be one of `specs` that is not fixed, its value of its type
/// and range (parseParamValue, context `command`); then the defaults of those not given (an empty
/// default: unset) are filled into `mods`. False with one line: "--gmon has no modifier 'mdoe'
/// (did you mean mode?) (accepted: mode, gini, diag, ci, ciaovs, residual)", or parseParamValue's.
bool checkModifiers(const std::string& command, const std::vector<ParamSpec>& specs,
                    std::map<std::string, std::string>& mods, std::string& err);

/// The one way a command reads its modifiers back: the typed value of modifier `name` of a
/// command whose modifiers are `specs`, once the one check (checkModifiers) has accepted them and
/// filled in their defaults. A modifier without a default that was not given is unset:
/// ParamValue{} (empty text, numbers 0); `mods.count(name)` says whether it was given.
ParamValue modifierValue(const std::vector<ParamSpec>& specs,
                         const std::map<std::string, std::string>& mods, const std::string& name);
/// The elements of list modifier `name` (ParamSpec::list), typed; empty when unset.
std::vector<ParamValue> modifierList(const std::vector<ParamSpec>& specs,
                                     const std::map<std::string, std::string>& mods,
                                     const std::string& name);

/// Moves the modifiers of `specs` out of `mods` into `out`, each parsed (parseParamValue, context
/// `command`; an empty text is an error there, as any text its type refuses). The modifiers of a
/// layer (ci, keeplight) are taken so, and the rest are the operation's own parameters. False with
/// parseParamValue's line.
bool takeModifiers(const std::string& command, const std::vector<ParamSpec>& specs,
                   std::map<std::string, std::string>& mods, ParamValues& out, std::string& err);

/// The one grammar of parameter text: "key=value:key=value", as a command's modifiers are written
/// (`--gmon:mode=channel:diag=1`) and as an operation's parameters are stored in a statistics file
/// (FORMAT.md "State parts with an owner"). As in oiiotool, a value may hold ':' where what follows
/// cannot start a key (a digit, a sign, a dot): "compression=dwaa:45". A key given twice is
/// refused (which one would count is a guess). On failure `problem` is one line without context.
/// Empty text is no keys.
bool parseParamText(const std::string& text, std::map<std::string, std::string>& kv,
                    std::string& problem);
/// Splits "NAME:key=value:key=value" at its first ':' into NAME and its parameters
/// (parseParamText): a command with its modifiers (`--gmon:mode=channel:diag=1`), an operation the
/// renderer runs online (`mcstat-render --online NAME:key=value`). No ':' is no parameters. `name`
/// is set even on failure, when `problem` is parseParamText's line.
bool parseNamedParams(const std::string& text, std::string& name,
                      std::map<std::string, std::string>& kv, std::string& problem);
/// `kv` in that grammar, keys in the map's order: what parseParamText reads back as `kv`.
std::string paramText(const std::map<std::string, std::string>& kv);
/// The shortest text of `v` that parseRealText reads back as exactly `v` ("0.2126", not
/// "0.21260000000000001"): parameter text that people read and that gives its values back.
std::string realText(double v);

/// The low-level number syntax parseParamValue uses (and nothing else does): the whole text is a
/// base-10 integer / a finite number, without surrounding spaces.
bool parseIntegerText(const std::string& text, int64_t& out);
bool parseRealText(const std::string& text, double& out);
/// Three comma-separated reals ("0.2126,0.7152,0.0722": luminance weights stored in a state
/// part's parameter text), each as parseRealText reads it; false unless exactly three.
bool parseRealTriple(const std::string& text, std::array<double, 3>& out);
/// The whole text is a base-10 integer in [lo, hi] (parseIntegerText's syntax): the options and
/// arguments that are no ParamSpec (`mcstat --threads N`, `mcstat-render --spp N`). False with
/// one line in `err`: "<what>: expected an integer, got '<text>'" or "<what>: must be between
/// <lo> and <hi> (got <value>)".
bool parseInt(const std::string& text, const std::string& what, int64_t lo, int64_t hi,
              int64_t& out, std::string& err);
/// The whole text is a base-10 integer in [0, 2^64 - 1] (seeds), no sign, no spaces.
bool parseUnsignedText(const std::string& text, uint64_t& out);

// ---- declaring parameters: the spellings every operation uses ----------------------------------

/// A finite number in [lo, hi] (lo excluded when loOpen; +-HUGE_VAL: unbounded).
ParamSpec realParam(const std::string& name, double lo, double hi, bool loOpen,
                    const std::string& def, const std::string& help, bool fixed = false);
/// An integer in [lo, hi].
ParamSpec intParam(const std::string& name, double lo, double hi, const std::string& def,
                   const std::string& help);
/// A 0/1 switch (also true/false, on/off).
ParamSpec flagParam(const std::string& name, const std::string& def, const std::string& help);
/// Any text; an empty `def` means the parameter is unset unless given.
ParamSpec textParam(const std::string& name, const std::string& def, const std::string& help);
/// One of `choices` (the first is not implied: `def` is the default), with other spellings.
ParamSpec enumParam(const std::string& name, std::vector<std::string> choices,
                    const std::string& def, const std::string& help,
                    std::vector<std::pair<std::string, std::string>> aliases = {});

}  // namespace mcstat
