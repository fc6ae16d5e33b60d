#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/pixel/gmonb.h"
#include "mcstat/filters/pixel/meridian.h"
#include "mcstat/filters/pixel/myriad.h"
#include "mcstat/filters/pixel/tmpe.h"
#include "mcstat/filters/registry.h"
#include "mcstat/filters/window/window_rank.h"
#include "mcstat/image/imageops.h"

using namespace mcstat;

namespace {

/// `op`'s parameters: `kv` over the defaults (the test fails on a parse error).
ParamValues valuesOf(const char* name, const std::map<std::string, std::string>& kv = {}) {
    ParamValues v;
    std::string err;
    EXPECT_TRUE(parseOperationParams(*findOperation(name), kv, v, err)) << name << ": " << err;
    return v;
}

const std::array<double, 3> kLuma{0.2126, 0.7152, 0.0722};

/// One grey pixel of buffers `v` (counts 1) through `name`'s bound kernel.
float greyEstimate(const char* name, const std::map<std::string, std::string>& kv,
                   std::vector<float> v) {
    std::vector<float> mean, count(v.size(), 1.f);
    for (float x : v) mean.insert(mean.end(), {x, x, x});
    const PixelKernel k = findOperation(name)->bindPixel(valuesOf(name, kv), kLuma);
    EstimatorScratch s;
    PixelEstimate e;
    k.estimate({mean.data(), count.data(), int(v.size())}, e, s);
    return e.rgb[0];
}

}  // namespace

TEST(Registry, TheEstimatorsAreTheBufferMeansOperations) {
    std::vector<const Operation*> bufferMeans;
    for (const Operation& op : operationRegistry())
        if (op.input == InputKind::BufferMeans) bufferMeans.push_back(&op);
    ASSERT_EQ(estimatorRegistry().size(), bufferMeans.size());
    for (size_t i = 0; i < bufferMeans.size(); ++i) {
        const Operation& e = estimatorRegistry()[i];
        EXPECT_EQ(e.name, bufferMeans[i]->name);  // in registry order
        EXPECT_NE(e.bindPixel, nullptr) << e.name;
        EXPECT_EQ(findEstimator(e.name)->name, e.name);
    }
    EXPECT_EQ(findEstimator("nope"), nullptr);
    for (const Operation& op : operationRegistry()) {
        if (op.input != InputKind::BufferMeans) {
            EXPECT_EQ(findEstimator(op.name), nullptr);
        }
    }
}

TEST(Registry, ParametersBindToTheKernel) {
    // {1, 1, 1, 1, 10}: G = (-4 - 2 + 0 + 2 + 40) / (5 * 14) = 0.514 (eq. 4)
    const std::vector<float> v = {1, 1, 1, 1, 10};
    EXPECT_EQ(greyEstimate("gmonb", {}, v), 1.f);                                   // G > 0.25: MoN
    EXPECT_FLOAT_EQ(greyEstimate("gmonb", {{"threshold", "0.6"}}, v), 14.f / 5.f);  // the mean
    // TMPE: alpha 0.2 trims one of five from each side, 0 none, 0.5 down to the median
    const std::vector<float> w = {1, 2, 3, 4, 100};
    EXPECT_FLOAT_EQ(greyEstimate("tmpe", {{"alpha", "0.2"}}, w), 3.f);
    EXPECT_FLOAT_EQ(greyEstimate("tmpe", {{"alpha", "0"}}, w), 22.f);
    EXPECT_FLOAT_EQ(greyEstimate("tmpe", {{"alpha", "0.5"}}, w), 3.f);
    // myriad: an absolute gamma far above the range is the mean; a relative one is scaled
    EXPECT_NEAR(greyEstimate("myriad", {{"gamma", "1e8"}, {"scale", "abs"}}, {1, 4, 3, 50}),
                58.f / 4.f, 1e-4);
    // meridian: a tiny delta selects the most frequent value
    EXPECT_EQ(greyEstimate("meridian", {{"delta", "1e-9"}, {"scale", "abs"}}, {3, 1, 2, 1}), 1.f);
    // mode binds the kernel's mode; luminance is the default
    EXPECT_EQ(findOperation("gmonb")->bindPixel(valuesOf("gmonb"), kLuma).mode,
              EstimatorMode::Luminance);
    EXPECT_EQ(
        findOperation("gmonb")->bindPixel(valuesOf("gmonb", {{"mode", "channel"}}), kLuma).mode,
        EstimatorMode::PerChannel);
}

TEST(Registry, SmallestRobustMFollowsTheParameters) {
    auto minM = [](const char* name, const std::map<std::string, std::string>& kv = {}) {
        return findOperation(name)->bindPixel(valuesOf(name, kv), kLuma).smallestRobustM;
    };
    EXPECT_EQ(minM("mean"), 1);
    EXPECT_EQ(minM("mon"), 3);
    EXPECT_EQ(minM("median"), 3);
    EXPECT_EQ(minM("gmon"), 4);
    EXPECT_EQ(minM("gmonb"), 3);
    EXPECT_EQ(minM("tmpe"), 4);                       // floor(0.25 M) >= 1 from M = 4
    EXPECT_EQ(minM("tmpe", {{"alpha", "0.5"}}), 3);   // the median's
    EXPECT_EQ(minM("tmpe", {{"alpha", "0.1"}}), 10);  // floor(0.1 M + 1e-9) >= 1
    EXPECT_GT(minM("tmpe", {{"alpha", "0"}}), 999);   // the mean at every M
    EXPECT_EQ(minM("myriad"), 2);
    EXPECT_EQ(minM("meridian"), 2);
}

TEST(Registry, RejectsUnknownAndBadParameters) {
    ParamValues p;
    std::string err;
    EXPECT_FALSE(parseOperationParams(*findOperation("gmon"), {{"treshold", "1"}}, p, err));
    EXPECT_NE(err.find("'treshold'"), std::string::npos) << err;
    EXPECT_NE(err.find("accepted: mode"), std::string::npos) << err;
    EXPECT_FALSE(parseOperationParams(*findOperation("mean"), {{"mode", "lum"}}, p, err));
    EXPECT_NE(err.find("no parameters"), std::string::npos) << err;
    EXPECT_FALSE(parseOperationParams(*findOperation("gmon"), {{"mode", "hsv"}}, p, err));
    EXPECT_FALSE(parseOperationParams(*findOperation("gmonb"), {{"threshold", "1.5"}}, p, err));
    EXPECT_FALSE(parseOperationParams(*findOperation("gmonb"), {{"threshold", "0.2x"}}, p, err));
    EXPECT_FALSE(parseOperationParams(*findOperation("gmonb"), {{"threshold", "nan"}}, p, err));
    struct Bad {
        const char *est, *key, *value, *needle;
    } bad[] = {{"tmpe", "alpha", "0.6", "alpha must be a number in [0, 0.5], not '0.6'"},
               {"tmpe", "alpha", "-0.1", "alpha"},
               {"tmpe", "alpha", "x", "alpha"},
               {"myriad", "gamma", "0", "gamma must be a finite number > 0, not '0'"},
               {"myriad", "gamma", "-1", "gamma"},
               {"myriad", "gamma", "inf", "gamma"},
               {"meridian", "delta", "1e999", "delta"},
               {"meridian", "scale", "log", "scale must be 'hampel', 'rel' or 'abs'"},
               {"tmpe", "gamma", "1", "has no parameter 'gamma'"},
               {"myriad", "delta", "1", "has no parameter 'delta'"}};
    for (const Bad& b : bad) {
        EXPECT_FALSE(parseOperationParams(*findOperation(b.est), {{b.key, b.value}}, p, err))
            << b.est << " " << b.key;
        EXPECT_NE(err.find(b.needle), std::string::npos) << err;
    }
}

TEST(Registry, TheParameterStructsDefaultsAreTheRegistrys) {
    // A caller that fills a kernel's struct by hand (tests, benchmarks) gets the registry's
    // estimator.
    auto def = [](const char* op, const char* key) {
        return std::stod(findOperation(op)->param(key)->defaultValue);
    };
    EXPECT_EQ(GmonbParams().threshold, def("gmonb", "threshold"));
    EXPECT_EQ(TmpeParams().alpha, def("tmpe", "alpha"));
    EXPECT_EQ(MyriadParams().gamma, def("myriad", "gamma"));
    EXPECT_EQ(MeridianParams().delta, def("meridian", "delta"));
    EXPECT_EQ(MyriadParams().scale, ScaleRule::Hampel);
    EXPECT_EQ(MeridianParams().scale, ScaleRule::Hampel);
    EXPECT_EQ(findOperation("myriad")->param("scale")->defaultValue, "hampel");
    EXPECT_EQ(findOperation("meridian")->param("scale")->defaultValue, "hampel");
    EXPECT_EQ(GmonParams().gini, GiniInput::Magnitudes);
    EXPECT_EQ(GmonbParams().gini, GiniInput::Magnitudes);
    EXPECT_EQ(findOperation("gmon")->param("gini")->defaultValue, "abs");
    EXPECT_EQ(findOperation("gmonb")->param("gini")->defaultValue, "abs");
    EXPECT_EQ(PixelParams().mode, EstimatorMode::Luminance);
}

// ---- the operation registry (every kind of operation, typed parameters) ------------------------

TEST(Operations, EveryOperationIsComplete) {
    std::vector<std::string> names;
    for (const Operation& op : operationRegistry()) {
        EXPECT_EQ(std::count(names.begin(), names.end(), op.name), 0) << op.name;
        names.push_back(op.name);
        EXPECT_FALSE(op.title.empty()) << op.name;
        EXPECT_FALSE(op.help.empty()) << op.name;
        EXPECT_FALSE(op.equation.empty()) << op.name;
        EXPECT_EQ(findOperation(op.name), &op);
        switch (op.input) {
            case InputKind::BufferMeans:
                EXPECT_NE(op.bindPixel, nullptr) << op.name;
                EXPECT_NE(findEstimator(op.name), nullptr) << op.name;
                break;
            case InputKind::Neighbourhood:
                EXPECT_NE(op.over, Neighbourhood::None) << op.name;
                EXPECT_NE(op.bindWindow, nullptr) << op.name;
                EXPECT_EQ(findEstimator(op.name), nullptr) << op.name;
                break;
            case InputKind::Samples:
                EXPECT_NE(op.samples, nullptr) << op.name;
                EXPECT_EQ(findEstimator(op.name), nullptr) << op.name;
                break;
        }
        for (const ParamSpec& p : op.params) {
            EXPECT_FALSE(p.help.empty()) << op.name << " " << p.name;
            EXPECT_EQ(op.param(p.name), &p) << op.name << " " << p.name << " twice";
        }
    }
}

TEST(Operations, EveryKernelBindsItsDefaults) {
    // Every operation binds its own defaults to its kernel: per pixel, a finite estimate of a
    // finite pixel; over a window, the window the "size" parameter says, centred (halo = size / 2).
    const std::vector<float> mean = {1, 2, 3, 9, 9, 9, 2, 2, 2, 1e3f, 0, 1}, count = {4, 4, 4, 4};
    for (const Operation& op : operationRegistry()) {
        ParamValues v;
        std::string err;
        ASSERT_TRUE(parseOperationParams(op, {}, v, err)) << err;
        if (op.bindPixel) {
            const PixelKernel k = op.bindPixel(v, kLuma);
            EstimatorScratch s;
            PixelEstimate e;
            k.estimate({mean.data(), count.data(), 4}, e, s);
            for (float c : e.rgb) EXPECT_TRUE(std::isfinite(c)) << op.name;
            EXPECT_GE(k.smallestRobustM, 1) << op.name;
        }
        if (op.bindWindow) {
            const WindowKernel k = op.bindWindow(v, kLuma);
            EXPECT_EQ(k.over, op.over) << op.name;
            EXPECT_EQ(k.haloX(), int(v.at("size").integer) / 2) << op.name;
            EXPECT_EQ(k.haloY(), int(v.at("size").integer2) / 2) << op.name;
            // its defaults prepare a pass over a one-pixel input of its kind
            const float rgb[3] = {1.f, 2.f, 3.f}, n[1] = {1.f};
            const RGBImageView image{rgb, 1, 1};
            const PixelBuffers one{rgb, n, 1};
            const BufferView buffers{1, 1, &one, [](const void* c, int, int) {
                                         return *static_cast<const PixelBuffers*>(c);
                                     }};
            const WindowInput in = k.over == Neighbourhood::Image ? WindowInput{&image, nullptr}
                                                                  : WindowInput{nullptr, &buffers};
            const auto pass = k.begin(in, 0, 0, 1, 1, 1, err);
            ASSERT_TRUE(pass) << op.name << ": " << err;
            const auto scratch = pass->newScratch();
            PixelEstimate e;
            pass->filterPixel(0, 0, e, *scratch);
            EXPECT_EQ(e.rgb, (std::array<float, 3>{1.f, 2.f, 3.f})) << op.name;
            // and refuse an input of the other kind in one line
            const WindowInput other = k.over == Neighbourhood::Image
                                          ? WindowInput{nullptr, &buffers}
                                          : WindowInput{&image, nullptr};
            EXPECT_FALSE(k.begin(other, 0, 0, 1, 1, 1, err)) << op.name;
            EXPECT_FALSE(err.empty()) << op.name;
        }
    }
}

TEST(Operations, EveryDefaultParsesWithinItsRange) {
    for (const Operation& op : operationRegistry()) {
        ParamValues values;
        std::string err;
        ASSERT_TRUE(parseOperationParams(op, {}, values, err)) << op.name << ": " << err;
        EXPECT_EQ(values.size(), op.params.size()) << op.name;
        for (const ParamSpec& p : op.params) {
            ParamValue v;
            ASSERT_TRUE(parseParamValue(op.name, p, p.defaultValue, v, err)) << err;
            switch (p.type) {
                case ParamType::Text:  // anything
                    break;
                case ParamType::Int:
                    EXPECT_GE(double(v.integer), p.min) << op.name << " " << p.name;
                    EXPECT_LE(double(v.integer), p.max) << op.name << " " << p.name;
                    break;
                case ParamType::Real:
                    EXPECT_TRUE(p.minOpen ? v.real > p.min : v.real >= p.min) << op.name << p.name;
                    EXPECT_LE(v.real, p.max) << op.name << " " << p.name;
                    break;
                case ParamType::Size:
                    EXPECT_GE(double(std::min(v.integer, v.integer2)), p.min) << op.name;
                    EXPECT_LE(double(std::max(v.integer, v.integer2)), p.max) << op.name;
                    break;
                case ParamType::Enum:
                    EXPECT_EQ(std::count(p.choices.begin(), p.choices.end(), v.text), 1) << op.name;
                    break;
                case ParamType::Flag:
                    EXPECT_TRUE(v.integer == 0 || v.integer == 1);
                    break;
            }
        }
    }
}

/// Values `p` must refuse: garbage, and just outside its range.
std::vector<std::string> badValues(const ParamSpec& p) {
    auto num = [](double v) {
        std::ostringstream s;
        s.precision(17);
        s << v;
        return s.str();
    };
    if (p.type == ParamType::Text) return {};  // any text is one
    std::vector<std::string> bad = {"", "x", " 1", "1 ", "nan", "inf"};
    switch (p.type) {
        case ParamType::Text:
            break;
        case ParamType::Int:
            bad.insert(bad.end(), {num(p.min - 1), num(p.max + 1), "1.5", "3x3"});
            if (p.odd) bad.push_back(num(p.min + 1));
            break;
        case ParamType::Real:
            bad.push_back(num(p.minOpen ? p.min : p.min - 1));
            if (p.max != HUGE_VAL) bad.push_back(num(p.max + 1));
            bad.push_back("1e999");
            bad.push_back("0.2x");
            break;
        case ParamType::Size:
            bad.insert(bad.end(),
                       {num(p.min - 1), num(p.max + 2), "3y3", "3x", "x3", "3x3x3", "1.0"});
            if (p.odd) bad.insert(bad.end(), {"2x3", "3x2", "4"});
            break;
        case ParamType::Enum:
            bad.insert(bad.end(), {"bogus", p.choices[0] + " "});
            break;
        case ParamType::Flag:
            bad.insert(bad.end(), {"2", "yes"});
            break;
    }
    return bad;
}

TEST(Operations, BadValuesAreOneLineErrors) {
    for (const Operation& op : operationRegistry()) {
        for (const ParamSpec* p : op.settable()) {
            for (const std::string& text : badValues(*p)) {
                ParamValues values;
                std::string err;
                EXPECT_FALSE(parseOperationParams(op, {{p->name, text}}, values, err))
                    << op.name << " " << p->name << "=" << text;
                EXPECT_EQ(err, op.name + ": " + p->name + " must be " + describeParam(*p) +
                                   ", not '" + text + "'");
                EXPECT_EQ(err.find('\n'), std::string::npos) << err;
            }
        }
    }
    // the wording of each type
    std::string err;
    ParamValues v;
    EXPECT_FALSE(parseOperationParams(*findOperation("3dwtmf"), {{"size", "2x3"}}, v, err, "--x"));
    EXPECT_EQ(err, "--x: size must be KxL with odd K, L in [1, 255] (e.g. 3x3), not '2x3'");
    EXPECT_FALSE(parseOperationParams(*findOperation("3dwmf"), {{"w", "0"}}, v, err));
    EXPECT_EQ(err, "3dwmf: w must be an integer in [1, 1000000], not '0'");
    EXPECT_FALSE(parseOperationParams(*findOperation("3dmf"), {{"mode", "hue"}}, v, err));
    EXPECT_EQ(err, "3dmf: mode must be 'lum' or 'channel', not 'hue'");
    // fixed parameters are not settable
    EXPECT_FALSE(parseOperationParams(*findOperation("3dmf"), {{"w", "3"}}, v, err));
    EXPECT_EQ(err, "estimator '3dmf' has no parameter 'w' (accepted: size, mode)");
}

TEST(Operations, GoodValuesParse) {
    ParamValues v;
    std::string err;
    ASSERT_TRUE(parseOperationParams(
        *findOperation("3dwtmf"), {{"size", "5x3"}, {"w", "7"}, {"alpha", "0.1"}, {"mode", "rgb"}},
        v, err))
        << err;
    const SpatialParams p = spatialParams(v, {0.2, 0.7, 0.1});
    EXPECT_EQ(p.windowWidth, 5);
    EXPECT_EQ(p.windowHeight, 3);
    EXPECT_EQ(p.centreWeight, 7);
    EXPECT_EQ(p.alpha, 0.1);
    EXPECT_EQ(p.mode, EstimatorMode::PerChannel);
    EXPECT_EQ(p.luma[1], 0.7);
    ASSERT_TRUE(parseOperationParams(*findOperation("mif"), {{"size", "7"}}, v, err)) << err;
    EXPECT_EQ(v.at("size").integer, 7);
    EXPECT_EQ(v.at("size").integer2, 7);
    int64_t i = 0;
    double d = 0.0;
    EXPECT_TRUE(parseIntegerText("-12", i));
    EXPECT_EQ(i, -12);
    EXPECT_FALSE(parseIntegerText("99999999999999999999", i));
    EXPECT_FALSE(parseIntegerText("1e3", i));
    EXPECT_TRUE(parseRealText("1e3", d));
    EXPECT_EQ(d, 1000.0);
    EXPECT_FALSE(parseRealText("1e400", d));
}

TEST(Operations, SpatialParamsDefaultsAreTheRegistrys) {
    // SpatialParams{} is MIF / 3DMF with the registry's defaults; every neighbourhood operation's
    // defaults are valid, and the fixed values are what the thesis' filters mean.
    const SpatialParams d;
    for (const char* n : {"mif", "3dmf"}) {
        ParamValues v;
        std::string err;
        ASSERT_TRUE(parseOperationParams(*findOperation(n), {}, v, err)) << err;
        const SpatialParams r = spatialParams(v, d.luma);
        EXPECT_EQ(r.windowWidth, d.windowWidth) << n;
        EXPECT_EQ(r.windowHeight, d.windowHeight) << n;
        EXPECT_EQ(r.centreWeight, d.centreWeight) << n;
        EXPECT_EQ(r.alpha, d.alpha) << n;
        EXPECT_EQ(r.mode, d.mode) << n;
    }
    struct Want {
        const char* op;
        int64_t w;
        double alpha;
    } want[] = {{"mif", 1, 0.5},
                {"wmif", 3, 0.5},
                {"3dmf", 1, 0.5},
                {"3dwmf", 3, 0.5},
                {"3dwtmf", 3, 0.25}};
    for (const Want& w : want) {
        ParamValues v;
        std::string err;
        ASSERT_TRUE(parseOperationParams(*findOperation(w.op), {}, v, err)) << err;
        const SpatialParams r = spatialParams(v, {0.2126, 0.7152, 0.0722});
        EXPECT_EQ(r.centreWeight, w.w) << w.op;
        EXPECT_EQ(r.alpha, w.alpha) << w.op;
        EXPECT_TRUE(validateSpatialParams(r, err)) << w.op << ": " << err;
    }
}

// A Samples operation is one registry entry: its SamplesFn gets the path and the parsed parameters,
// and runSamplesOperation (what `mcstat --NAME` and the plugin call) makes the image of it.
// The two files it is run on (written by the test: runSamplesOperation opens the file and hands
// the operation a SampleSource).
std::string fakeFile(const char* name) {
    return std::string(MCSTAT_BINARY_DIR) + "/tests/filters/" + name;
}

bool fakeSamples(const SamplesRequest& req, OperationImage& out, std::string& err) {
    if (req.source == nullptr || req.source->header().width != 2) {
        err = "no source";
        return false;
    }
    if (req.path != fakeFile("f.mcstat")) {
        err = req.path + ": no per-sample part";
        return false;
    }
    out.width = 2;
    out.height = 1;
    out.channels = {"R", "G", "B", "modes"};
    const float v = float(req.params->at("bandwidth").real);
    out.pixels = {v, v, v, 1.f, 2 * v, 2 * v, 2 * v, 2.f};
    return true;
}

TEST(Operations, SamplesOperationsRunThroughTheirFunction) {
    Operation op;
    op.name = "fake";
    op.input = InputKind::Samples;
    op.samples = &fakeSamples;
    ParamSpec bw;
    bw.name = "bandwidth";
    bw.min = 0.0;
    bw.minOpen = true;
    bw.max = 10.0;
    bw.defaultValue = "0.5";
    bw.help = "h";
    op.params = {bw};
    ParamValues v;
    std::string err;
    ASSERT_TRUE(parseOperationParams(op, {{"bandwidth", "2"}}, v, err)) << err;
    StatsImage file;
    file.header.width = 2;
    file.header.height = 1;
    file.header.originX = 5;
    ASSERT_TRUE(file.allocate(err)) << err;
    ASSERT_TRUE(writeStatsFile(fakeFile("f.mcstat"), file, err)) << err;
    ASSERT_TRUE(writeStatsFile(fakeFile("g.mcstat"), file, err)) << err;
    const StatsHeader h = file.header;
    OIIO::ImageBuf img;
    ASSERT_TRUE(runSamplesOperation(img, fakeFile("f.mcstat"), h, op, v, {0.2, 0.7, 0.1}))
        << img.geterror();
    EXPECT_EQ(img.spec().x, 5);
    EXPECT_EQ(img.spec().channelnames, (std::vector<std::string>{"R", "G", "B", "modes"}));
    EXPECT_EQ(img.getchannel(6, 0, 0, 0), 4.f);
    EXPECT_FALSE(runSamplesOperation(img, fakeFile("g.mcstat"), h, op, v, {0.2, 0.7, 0.1}));
    EXPECT_EQ(img.geterror(), fakeFile("g.mcstat") + ": no per-sample part");
    EXPECT_FALSE(runSamplesOperation(img, fakeFile("none.mcstat"), h, op, v, {0.2, 0.7, 0.1}));
    StatsHeader wider = h;
    wider.width = 3;  // a result of the wrong size is refused
    EXPECT_FALSE(runSamplesOperation(img, fakeFile("f.mcstat"), wider, op, v, {0.2, 0.7, 0.1}));
    // and a statistics image in memory cannot feed it
    EXPECT_FALSE(applyOperation(img, StatsImage(), op, v, {0.2, 0.7, 0.1}));
}
