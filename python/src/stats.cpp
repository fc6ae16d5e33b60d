// Statistics files for Python: read, write, ingest, blocks of rows, and their arrays as numpy
// views (docs/python.md).
#include <cmath>
#include <limits>

#include "bindings.h"
#include "mcstat/ingest/ingest.h"

namespace mcstat::python {

namespace {

py::dict windowDict(int x, int y, int w, int h) {
    py::dict d;
    d["x"] = x;
    d["y"] = y;
    d["width"] = w;
    d["height"] = h;
    return d;
}

/// A float32 view of `data` (shape `shape`, C order) kept alive by `owner`; None when empty.
py::object view(std::vector<float>& data, std::vector<py::ssize_t> shape, const py::object& owner) {
    if (data.empty()) return py::none();
    return py::array_t<float>(shape, data.data(), owner);
}

/// Adaptive layout: pixel p's m_p buffers padded to M with NaN means and count 0.
py::array_t<float> padded(const StatsImage& img, const std::vector<float>& data, size_t per,
                          float fill) {
    const StatsHeader& h = img.header;
    const size_t M = size_t(h.M);
    py::array_t<float> out(
        {py::ssize_t(h.height), py::ssize_t(h.width), py::ssize_t(M), py::ssize_t(per)});
    float* o = out.mutable_data();
    {
        py::gil_scoped_release release;
        for (size_t p = 0; p < img.pixelCount(); ++p) {
            const size_t k = img.bufferBegin(p), m = size_t(img.buffersOf(p));
            for (size_t j = 0; j < M; ++j)
                for (size_t c = 0; c < per; ++c)
                    o[(p * M + j) * per + c] = j < m ? data[(k + j) * per + c] : fill;
        }
    }
    return out;
}

py::dict arrays(const py::object& self) {
    NativeStats& n = self.cast<NativeStats&>();
    StatsImage& img = *n.img;
    const StatsHeader& h = img.header;
    const py::ssize_t H = h.height, W = h.width, M = h.M, A = py::ssize_t(h.aovs.size());
    py::dict d;
    d["mean"] = view(img.beauty, {H, W, 3}, self);
    if (!h.adaptiveM) {
        d["buffers"] = view(img.bufferMean, {H, W, M, 3}, self);
        d["counts"] = view(img.bufferCount, {H, W, M}, self);
        d["aov"] = view(img.aov, {H, W, M, A}, self);
    } else {
        const float nan = std::numeric_limits<float>::quiet_NaN();
        if (!img.bufferMean.empty()) {
            d["buffers"] = padded(img, img.bufferMean, 3, nan);
            d["counts"] = padded(img, img.bufferCount, 1, 0.0f).attr("reshape")(H, W, M);
            py::array_t<int32_t> m({H, W});
            for (size_t p = 0; p < img.pixelCount(); ++p) m.mutable_data()[p] = img.buffersOf(p);
            d["buffers_per_pixel"] = m;
        }
        d["aov"] = A > 0 && !img.aov.empty() ? py::object(padded(img, img.aov, size_t(A), nan))
                                             : py::object(py::none());
    }
    d["count"] = view(img.count, {H, W}, self);
    d["moments_mean"] = view(img.mean, {H, W, 3}, self);
    d["variance"] = view(img.variance, {H, W, 3}, self);
    d["spread"] = view(img.spread, {H, W, kSpreadFloats}, self);
    py::dict f;
    f["N"] = view(img.normal, {H, W, 3}, self);
    f["P"] = view(img.position, {H, W, 3}, self);
    f["Albedo"] = view(img.albedo, {H, W, 3}, self);
    f["Z"] = view(img.depth, {H, W}, self);
    f["A"] = view(img.coverage, {H, W}, self);
    d["features"] = f;
    return d;
}

std::shared_ptr<NativeStats> readFile(const std::string& path) {
    auto n = std::make_shared<NativeStats>();
    n->img = std::make_shared<StatsImage>();
    n->name = path;
    std::string err;
    {
        py::gil_scoped_release release;
        if (!checkStatsPath(path, err) || !readStatsFile(path, *n->img, err)) throw Error(err);
    }
    return n;
}

void writeFile(const NativeStats& n, const std::string& path) {
    std::string err;
    py::gil_scoped_release release;
    if (!validateStats(*n.img, n.name, err) || !writeStatsFile(path, *n.img, err)) throw Error(err);
}

/// `mcstat --ingest PATTERN` with modifiers: the renders read into memory.
std::shared_ptr<NativeStats> ingest(const std::string& pattern,
                                    const std::map<std::string, std::string>& modifiers) {
    auto n = std::make_shared<NativeStats>();
    n->img = std::make_shared<StatsImage>();
    n->name = "ingest(" + pattern + ")";
    std::string err;
    py::gil_scoped_release release;
    IngestOptions opt;
    std::vector<std::string> paths;
    if (!parseIngestOptions(modifiers, opt, err, "--ingest")) throw Error(err);
    if (!expandInputs(pattern, paths, err)) throw Error("--ingest: " + err);
    IngestSource src;
    if (!src.init(paths, opt, err) || !readAll(src, *n->img, err)) throw Error("--ingest: " + err);
    n->img->header = src.header();  // the seeds: the renders' hashes, known after the pass
    return n;
}

/// Streams a statistics file by blocks of rows (StatsFileReader): each block its own image.
class BlockReader {
  public:
    explicit BlockReader(const std::string& path) {
        std::string err;
        py::gil_scoped_release release;
        if (!checkStatsPath(path, err) || !reader_.open(path, err)) throw Error(err);
    }
    py::dict header() const { return headerDict(reader_.header()); }
    int height() const { return reader_.header().height; }
    std::shared_ptr<NativeStats> read(int firstRow, int rows) {
        auto n = std::make_shared<NativeStats>();
        n->img = std::make_shared<StatsImage>();
        n->name = reader_.path();
        std::string err;
        py::gil_scoped_release release;
        if (!reader_.read(firstRow, rows, kStatsAllParts, *n->img, err)) throw Error(err);
        return n;
    }

  private:
    StatsFileReader reader_;
};

}  // namespace

namespace {

/// A comma-joined header list (seeds, features, sources) as a tuple of str, as beauty_channels
/// is: one type for every list in the header (an empty list: ()).
py::tuple listTuple(const std::string& text) {
    py::list items;
    size_t begin = 0;
    while (begin <= text.size()) {
        const size_t end = std::min(text.find(',', begin), text.size());
        if (end > begin) items.append(text.substr(begin, end - begin));
        begin = end + 1;
    }
    return py::tuple(items);
}

}  // namespace

py::dict headerDict(const StatsHeader& h) {
    py::dict d;
    d["format_version"] = h.formatVersion;
    d["width"] = h.width;
    d["height"] = h.height;
    d["data_window"] = windowDict(h.originX, h.originY, h.width, h.height);
    const bool display = h.displayWidth > 0;
    d["display_window"] =
        windowDict(display ? h.displayX : h.originX, display ? h.displayY : h.originY,
                   display ? h.displayWidth : h.width, display ? h.displayHeight : h.height);
    d["M"] = h.M;
    d["adaptive"] = h.adaptiveM;
    d["compact"] = h.compact;
    d["compact_rule"] = h.compactRule;
    d["spp"] = h.spp;
    d["assignment"] = h.assignment;
    d["renderer"] = h.renderer;
    d["color_space"] = h.colorSpace;
    d["seeds"] = listTuple(h.seeds);
    d["scene"] = h.scene;
    d["variance"] = h.variance;
    d["features"] = listTuple(featureListText(h.features));
    d["sources"] = listTuple(h.sources);
    d["state_owner"] = h.state.operation;  // the operation owning state parts, "" for none
    d["has_records"] = h.hasRecords;
    py::list aovs;
    for (const AovChannel& a : h.aovs) {
        py::dict c;
        c["name"] = a.name;
        c["class"] = aovClassName(a.cls);
        c["part"] = a.part;
        aovs.append(c);
    }
    d["aovs"] = aovs;
    d["beauty_channels"] = py::make_tuple(h.beautyNames[0], h.beautyNames[1], h.beautyNames[2]);
    d["beauty_part"] = h.beautyPart;
    d["source_metadata"] = h.sourceMetadata;
    return d;
}

void bindStats(py::module_& m) {
    py::class_<NativeStats, std::shared_ptr<NativeStats>>(m, "_Native")
        .def_property_readonly("name", [](const NativeStats& n) { return n.name; })
        .def_property_readonly("header",
                               [](const NativeStats& n) { return headerDict(n.img->header); })
        .def("arrays", &arrays, "the image's arrays as numpy views (no copy)");
    m.def("_read", &readFile, py::arg("path"));
    m.def("_write", &writeFile, py::arg("native"), py::arg("path"));
    m.def("_ingest", &ingest, py::arg("pattern"), py::arg("modifiers"));
    m.def("_read_header", [](const std::string& path) {
        StatsHeader h;
        std::string err;
        {
            py::gil_scoped_release release;
            if (!checkStatsPath(path, err) || !readStatsHeader(path, h, err)) throw Error(err);
        }
        return headerDict(h);
    });
    py::class_<BlockReader>(m, "_BlockReader")
        .def(py::init<const std::string&>())
        .def_property_readonly("header", &BlockReader::header)
        .def_property_readonly("height", &BlockReader::height)
        .def("read", &BlockReader::read, py::arg("first_row"), py::arg("rows"));
}

}  // namespace mcstat::python
