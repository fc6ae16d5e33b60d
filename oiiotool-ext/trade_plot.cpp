// --tradeplot TABLE (docs/trade.md): the speed/accuracy trade drawn from a table of measurements,
// one row per method, samples per pixel and seed (scripts/trade.sh writes it; any table with the
// named columns will do). Rows of one method and spp are averaged over their seeds, the spread
// drawn as bars from the smallest to the largest, one curve per method against wall time or bytes
// per pixel; rows of method "reference" give the reference's own noise floor, a dashed line.
// Columns are found by name, never by position. plot.cpp runs gnuplot.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/strutil.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <map>
#include <tuple>

#include "cli.h"
#include "mcstat/core/params.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/codec/temp_file.h"
#include "plot.h"

namespace mcstat::cli {

namespace {

using OIIO::Strutil::fmt::format;

/// The largest table read: a run of scripts/trade.sh writes well under 1 MB.
constexpr uintmax_t kMaxTableBytes = uintmax_t(64) << 20;
/// The method whose rows are the reference's own noise, not a curve.
const char* const kReferenceMethod = "reference";

const std::vector<ParamSpec>& tradePlotModifiers() {
    static const std::vector<ParamSpec> specs = {
        enumParam("x", {"seconds", "bytes"}, "seconds",
                  "the x axis: column seconds (wall time, render + estimate) or bytesPerPixel (the "
                  "files a method needs, on disk)"),
        enumParam("y", {"relMSE", "SSIM"}, "relMSE", "the y axis: column relMSE or SSIM"),
        textParam("scene", "",
                  "the rows whose column scene is this; needed when the table holds several"),
        textParam("methods", "",
                  "the curves, comma-separated, in this order (default: every method, "
                  "in the table's order)"),
        textParam("title", "", "the plot's title (default: the scene and the axes)"),
        textParam("csv", "",
                  "FILE: the points drawn, method,spp,seeds,x,y,yMin,yMax (y the mean over the "
                  "seeds)")};
    return specs;
}

/// Appends `value` to `list` unless it is there: the distinct values in order of appearance.
void addOnce(std::vector<std::string>& list, const std::string& value) {
    if (std::find(list.begin(), list.end(), value) == list.end()) list.push_back(value);
}

/// The table as read: its header's column names and its rows of text fields.
struct Table {
    std::vector<std::string> columns;
    std::vector<std::vector<std::string>> rows;
    std::vector<size_t> lines;  ///< each row's line number in the file, for messages
    int column(const std::string& name) const {
        const auto it = std::find(columns.begin(), columns.end(), name);
        return it == columns.end() ? -1 : int(it - columns.begin());
    }
};

/// Reads a comma-separated table with a header line; no quoting (the tool's tables have none).
bool readTable(const std::string& path, const std::string& cmd, Table& t, std::string& err) {
    const std::string shown = printable(path);
    if (!OIIO::Filesystem::is_regular(path)) {
        err = format("{}: {}: no such file", cmd, shown);
        return false;
    }
    const uintmax_t bytes = OIIO::Filesystem::file_size(path);
    if (bytes > kMaxTableBytes) {
        err = format("{}: {}: {} bytes, more than the {} a table may hold", cmd, shown, bytes,
                     kMaxTableBytes);
        return false;
    }
    std::ifstream f(path, std::ios::binary);
    std::string line;
    size_t number = 0;
    while (std::getline(f, line)) {
        ++number;
        if (!line.empty() && line.back() == '\r') line.pop_back();
        if (line.empty()) continue;
        if (line.find('"') != std::string::npos) {
            err = format("{}: {}: line {}: quoted fields are not read", cmd, shown, number);
            return false;
        }
        std::vector<std::string> fields;
        for (const auto& field : OIIO::Strutil::splitsv(line, ",")) fields.emplace_back(field);
        if (t.columns.empty()) {
            t.columns = fields;
            continue;
        }
        if (fields.size() != t.columns.size()) {
            err = format("{}: {}: line {} has {} fields, the header {}", cmd, shown, number,
                         fields.size(), t.columns.size());
            return false;
        }
        t.rows.push_back(std::move(fields));
        t.lines.push_back(number);
    }
    if (f.bad()) {
        err = format("{}: {}: cannot read", cmd, shown);
        return false;
    }
    if (t.rows.empty()) {
        err = format("{}: {}: no rows (a header line and one row per measurement)", cmd, shown);
        return false;
    }
    return true;
}

/// One measurement: a method at some spp with one seed.
struct Measurement {
    std::string method;
    double spp = 0.0, x = 0.0, y = 0.0;
};

/// One point drawn: a method's measurements at one spp, over their seeds.
struct TradePoint {
    std::string method;
    double spp = 0.0;
    size_t seeds = 0;
    double x = 0.0, y = 0.0, yMin = 0.0, yMax = 0.0;  ///< x, y: means; the y range over the seeds
};

/// What --tradeplot was asked.
struct TradeRequest {
    std::string cmd, path, xColumn, yColumn, scene, title, csvPath;
    std::vector<std::string> methods;  ///< empty: every method in the table's order
};

/// The rows of the request's scene as measurements, the numbers checked.
bool measurements(const Table& t, TradeRequest& q, std::vector<Measurement>& out,
                  std::string& err) {
    const std::string shown = printable(q.path);
    const int method = t.column("method"), spp = t.column("spp"), x = t.column(q.xColumn),
              y = t.column(q.yColumn), scene = t.column("scene");
    for (const auto& [name, at] : {std::pair<const char*, int>{"method", method},
                                   {"spp", spp},
                                   {q.xColumn.c_str(), x},
                                   {q.yColumn.c_str(), y}})
        if (at < 0) {
            err = format("{}: {}: no column {} (columns: {})", q.cmd, shown, name,
                         printableList(t.columns));
            return false;
        }
    std::vector<std::string> scenes;
    if (scene >= 0)
        for (const auto& row : t.rows) addOnce(scenes, row[size_t(scene)]);
    if (q.scene.empty() && scenes.size() > 1) {
        err = format("{}: {} holds {} scenes ({}): choose one with :scene=NAME", q.cmd, shown,
                     scenes.size(), printableList(scenes));
        return false;
    }
    if (!q.scene.empty() && std::find(scenes.begin(), scenes.end(), q.scene) == scenes.end()) {
        err = format("{}: {} has no rows of scene '{}' (scenes: {})", q.cmd, shown,
                     printable(q.scene), printableList(scenes));
        return false;
    }
    if (q.scene.empty() && scenes.size() == 1) q.scene = scenes[0];
    for (size_t r = 0; r < t.rows.size(); ++r) {
        const auto& row = t.rows[r];
        if (scene >= 0 && row[size_t(scene)] != q.scene) continue;
        Measurement m;
        m.method = row[size_t(method)];
        for (const auto& [column, at, value] :
             {std::tuple<std::string, int, double*>{"spp", spp, &m.spp},
              {q.xColumn, x, &m.x},
              {q.yColumn, y, &m.y}}) {
            if (!parseRealText(row[size_t(at)], *value)) {
                err = format("{}: {}: line {}: column {}: '{}' is not a finite number", q.cmd,
                             shown, t.lines[r], column, printable(row[size_t(at)]));
                return false;
            }
        }
        // The x axis is logarithmic: time and bytes are positive for anything measured.
        if (!(m.x > 0.0) && m.method != kReferenceMethod) {
            err = format("{}: {}: line {}: column {} must be positive, not {}", q.cmd, shown,
                         t.lines[r], q.xColumn, row[size_t(x)]);
            return false;
        }
        out.push_back(std::move(m));
    }
    return true;
}

/// The points: a method's measurements at one spp averaged, in the order of `methods` (or of the
/// table), each method's points by increasing spp.
std::vector<TradePoint> tradePoints(const std::vector<Measurement>& ms,
                                    std::vector<std::string>& methods) {
    if (methods.empty())
        for (const Measurement& m : ms)
            if (m.method != kReferenceMethod) addOnce(methods, m.method);
    std::vector<TradePoint> out;
    for (const std::string& method : methods) {
        std::map<double, std::vector<const Measurement*>> bySpp;
        for (const Measurement& m : ms)
            if (m.method == method) bySpp[m.spp].push_back(&m);
        for (const auto& [spp, group] : bySpp) {
            TradePoint p{method,
                         spp,
                         group.size(),
                         0.0,
                         0.0,
                         std::numeric_limits<double>::infinity(),
                         -std::numeric_limits<double>::infinity()};
            double sx = 0.0, sy = 0.0;  // in double, in the table's order
            for (const Measurement* m : group) {
                sx += m->x;
                sy += m->y;
                p.yMin = std::min(p.yMin, m->y);
                p.yMax = std::max(p.yMax, m->y);
            }
            p.x = sx / double(group.size());
            p.y = sy / double(group.size());
            out.push_back(p);
        }
    }
    return out;
}

std::string tradeScript(const TradeRequest& q, const std::vector<std::string>& methods, bool logY,
                        double floor) {
    const bool seconds = q.xColumn == "seconds";
    std::string title = q.title;
    if (title.empty())
        title = format("{}{} against {}", q.scene.empty() ? "" : q.scene + ": ", q.yColumn,
                       seconds ? "wall time" : "bytes per pixel");
    std::string s =
        "set terminal pngcairo noenhanced size 1100,640 font 'DejaVu Sans,11'\n"
        "set output 'plot.png'\n"
        "set title '" +
        plotSafe(title) +
        "'\n"
        "set grid\nset logscale x\n" +
        std::string(logY ? "set logscale y\n" : "unset logscale y\n") + "set xlabel '" +
        (seconds ? "seconds (render + estimate, this machine)" : "bytes per pixel (on disk)") +
        "'\nset ylabel '" + q.yColumn +
        " (mean over the seeds; bars: smallest to largest)'\n"
        "set key outside right top\n"
        "plot";
    for (size_t i = 0; i < methods.size(); ++i) {
        const bool mean = methods[i] == "mean";  // what every other method is weighed against
        s += format(
            "{} 'data.txt' index {} using 1:2:3:4 with yerrorlines lw {} lc {} pt {} "
            "title '{}'",
            i ? "," : "", i, mean ? 4 : 2, i % 8 + 1, i % 13 + 1, plotSafe(methods[i]));
    }
    if (std::isfinite(floor))
        s += format(
            ", {:.17g} with lines dt 2 lw 2 lc rgb '#555555' title 'the reference''s own "
            "noise'",
            floor);
    return s + "\n";
}

bool cmdTradePlot(State& st, const std::string& cmd, const std::vector<std::string>& args,
                  const Modifiers& mods, std::string& err) {
    const std::vector<ParamSpec>& specs = tradePlotModifiers();
    TradeRequest q;
    q.cmd = cmd;
    q.path = args[0];
    q.xColumn = modifierValue(specs, mods, "x").text == "bytes" ? "bytesPerPixel" : "seconds";
    q.yColumn = modifierValue(specs, mods, "y").text;
    q.scene = modifierValue(specs, mods, "scene").text;
    q.title = modifierValue(specs, mods, "title").text;
    q.csvPath = modifierValue(specs, mods, "csv").text;
    for (const std::string& m :
         OIIO::Strutil::splits(modifierValue(specs, mods, "methods").text, ","))
        if (!OIIO::Strutil::strip(m).empty()) q.methods.emplace_back(OIIO::Strutil::strip(m));
    if (!haveGnuplot(err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    Table t;
    std::vector<Measurement> ms;
    if (!readTable(q.path, cmd, t, err) || !measurements(t, q, ms, err)) return false;
    for (const std::string& m : q.methods)
        if (std::none_of(ms.begin(), ms.end(),
                         [&](const Measurement& x) { return x.method == m; })) {
            std::vector<std::string> known;
            for (const Measurement& x : ms) addOnce(known, x.method);
            err = format("{}: {} has no rows of method '{}' (methods: {})", cmd, printable(q.path),
                         printable(m), printableList(known, 64));
            return false;
        }
    std::vector<std::string> methods = q.methods;
    const std::vector<TradePoint> points = tradePoints(ms, methods);
    // The reference's own noise: the mean of its rows' y (relMSE only: an SSIM floor means little).
    double floor = std::numeric_limits<double>::quiet_NaN(), floorSum = 0.0;
    size_t floorRows = 0;
    for (const Measurement& m : ms)
        if (m.method == kReferenceMethod) floorSum += m.y, ++floorRows;
    if (floorRows && q.yColumn == "relMSE") floor = floorSum / double(floorRows);

    bool logY = q.yColumn == "relMSE";
    std::string data, csv = "method,spp,seeds,x,y,yMin,yMax\n";
    for (const std::string& method : methods) {
        std::vector<const TradePoint*> pts;
        for (const TradePoint& p : points)
            if (p.method == method) pts.push_back(&p);
        std::stable_sort(pts.begin(), pts.end(),
                         [](const TradePoint* a, const TradePoint* b) { return a->x < b->x; });
        data += format("# {}\n", method);
        for (const TradePoint* p : pts) {
            logY = logY && p->yMin > 0.0;  // a log axis cannot show 0
            data += format("{:.17g} {:.17g} {:.17g} {:.17g}\n", p->x, p->y, p->yMin, p->yMax);
            csv += format("{},{:.17g},{},{:.17g},{:.17g},{:.17g},{:.17g}\n", method, p->spp,
                          p->seeds, p->x, p->y, p->yMin, p->yMax);
        }
        data += "\n\n";
    }
    if (!q.csvPath.empty() && !writeTextAtomically(q.csvPath, csv, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    auto plot = std::make_shared<OIIO::ImageBuf>();
    if (!runGnuplot(tradeScript(q, methods, logY, floor), {{"data.txt", data}}, "plot.png", *plot,
                    err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    plot->specmod().attribute(kDisplayReferredAttr, 1);
    plot->specmod().attribute("mcstat:tradeplot:points", int(points.size()));
    Item out;
    out.name = format("tradeplot({})", q.path);
    out.image = plot;
    st.stack.push_back(std::move(out));
    return true;
}

}  // namespace

void appendTradeCommands(std::vector<Command>& t) {
    t.push_back({"--tradeplot", 1, "TABLE",
                 "Push a plot of the speed/accuracy trade (gnuplot): relMSE or SSIM against wall "
                 "time or bytes per pixel, one curve per method, averaged over seeds, from a table "
                 "with columns method, spp, seconds, bytesPerPixel, relMSE, SSIM (and scene) as "
                 "scripts/trade.sh writes it (docs/trade.md)",
                 tradePlotModifiers(), &cmdTradePlot, ""});
}

}  // namespace mcstat::cli
