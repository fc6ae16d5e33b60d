#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <sstream>

#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"
#include "mcstat/sample_records.h"
#include "mcstat/stats_file.h"

using namespace mcstat;

TEST(Registry, ListsTheEstimatorsOnce) {
    std::vector<std::string> names;
    for (const EstimatorInfo& e : estimatorRegistry()) {
        names.push_back(e.name);
        EXPECT_NE(e.fn, nullptr);
        EXPECT_FALSE(e.help.empty());
    }
    EXPECT_EQ(names, (std::vector<std::string>{"mean", "mon", "gmon", "gmonb", "median", "tmpe",
                                               "myriad", "meridian"}));
    EXPECT_EQ(findEstimator("gmon")->fn, &estimateGMoN);
    EXPECT_EQ(findEstimator("nope"), nullptr);
}

TEST(Registry, ParsesParametersAndDefaults) {
    EstimatorParams p;
    p.giniThreshold = 0.9;
    std::string err;
    ASSERT_TRUE(parseEstimatorParams(*findEstimator("gmonb"), {{"mode", "channel"}}, p, err));
    EXPECT_EQ(p.mode, EstimatorMode::PerChannel);
    EXPECT_DOUBLE_EQ(p.giniThreshold, 0.25);  // the default is applied when not given
    ASSERT_TRUE(parseEstimatorParams(*findEstimator("gmonb"), {{"threshold", "0.5"}}, p, err));
    EXPECT_DOUBLE_EQ(p.giniThreshold, 0.5);
    EXPECT_EQ(p.mode, EstimatorMode::Luminance);
}

TEST(Registry, RejectsUnknownAndBadParameters) {
    EstimatorParams p;
    std::string err;
    EXPECT_FALSE(parseEstimatorParams(*findEstimator("gmon"), {{"treshold", "1"}}, p, err));
    EXPECT_NE(err.find("'treshold'"), std::string::npos) << err;
    EXPECT_NE(err.find("accepted: mode"), std::string::npos) << err;
    EXPECT_FALSE(parseEstimatorParams(*findEstimator("mean"), {{"mode", "lum"}}, p, err));
    EXPECT_NE(err.find("no parameters"), std::string::npos) << err;
    EXPECT_FALSE(parseEstimatorParams(*findEstimator("gmon"), {{"mode", "hsv"}}, p, err));
    EXPECT_FALSE(parseEstimatorParams(*findEstimator("gmonb"), {{"threshold", "1.5"}}, p, err));
    EXPECT_FALSE(parseEstimatorParams(*findEstimator("gmonb"), {{"threshold", "0.2x"}}, p, err));
    EXPECT_FALSE(parseEstimatorParams(*findEstimator("gmonb"), {{"threshold", "nan"}}, p, err));
}

TEST(Registry, JungParameters) {
    EstimatorParams p;
    std::string err;
    ASSERT_TRUE(parseEstimatorParams(*findEstimator("tmpe"), {{"alpha", "0.5"}}, p, err)) << err;
    EXPECT_DOUBLE_EQ(p.alpha, 0.5);
    ASSERT_TRUE(parseEstimatorParams(*findEstimator("tmpe"), {}, p, err)) << err;
    EXPECT_DOUBLE_EQ(p.alpha, 0.25);
    ASSERT_TRUE(parseEstimatorParams(*findEstimator("myriad"), {{"gamma", "2.5"}, {"scale", "abs"}},
                                     p, err))
        << err;
    EXPECT_DOUBLE_EQ(p.gamma, 2.5);
    EXPECT_FALSE(p.scaleRelative);
    ASSERT_TRUE(parseEstimatorParams(*findEstimator("meridian"), {}, p, err)) << err;
    EXPECT_DOUBLE_EQ(p.delta, 0.05);
    EXPECT_TRUE(p.scaleRelative);
    // the struct's defaults are the registry's, so callers that skip parsing get the same estimator
    const EstimatorParams d;
    EXPECT_EQ(d.alpha, 0.25);
    EXPECT_EQ(d.gamma, 0.05);
    EXPECT_EQ(d.delta, 0.05);
    EXPECT_TRUE(d.scaleRelative);

    struct Bad {
        const char *est, *key, *value, *needle;
    } bad[] = {{"tmpe", "alpha", "0.6", "alpha must be a number in [0, 0.5], not '0.6'"},
               {"tmpe", "alpha", "-0.1", "alpha"},
               {"tmpe", "alpha", "x", "alpha"},
               {"myriad", "gamma", "0", "gamma must be a finite number > 0, not '0'"},
               {"myriad", "gamma", "-1", "gamma"},
               {"myriad", "gamma", "inf", "gamma"},
               {"meridian", "delta", "1e999", "delta"},
               {"meridian", "scale", "log", "scale must be 'rel' or 'abs'"},
               {"tmpe", "gamma", "1", "has no parameter 'gamma'"},
               {"myriad", "delta", "1", "has no parameter 'delta'"}};
    for (const Bad& b : bad) {
        EXPECT_FALSE(parseEstimatorParams(*findEstimator(b.est), {{b.key, b.value}}, p, err))
            << b.est << " " << b.key;
        EXPECT_NE(err.find(b.needle), std::string::npos) << err;
    }
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
                EXPECT_NE(op.fn, nullptr) << op.name;
                EXPECT_NE(findEstimator(op.name), nullptr) << op.name;
                break;
            case InputKind::Neighbourhood:
                EXPECT_NE(op.over, Neighbourhood::None) << op.name;
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
    for (const char* n : {"mif", "wmif", "3dmf", "3dwmf", "3dwtmf"}) {
        ASSERT_NE(findOperation(n), nullptr) << n;
        EXPECT_EQ(findOperation(n)->input, InputKind::Neighbourhood) << n;
    }
    EXPECT_EQ(findOperation("mif")->over, Neighbourhood::Image);
    EXPECT_EQ(findOperation("3dwtmf")->over, Neighbourhood::SubBuffers);
    EXPECT_EQ(findOperation("pajot")->input, InputKind::Samples);
    EXPECT_EQ(findOperation("rpf")->input, InputKind::Samples);
    EXPECT_EQ(estimatorRegistry().size() + 7, operationRegistry().size());
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
    std::vector<std::string> bad = {"", "x", " 1", "1 ", "nan", "inf"};
    switch (p.type) {
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

TEST(Operations, EstimatorParamsDefaultsAreTheRegistrys) {
    const EstimatorParams d;
    for (const EstimatorInfo& e : estimatorRegistry()) {
        EstimatorParams p;
        p.giniThreshold = p.alpha = p.gamma = p.delta = -1.0;
        p.scaleRelative = false;
        p.mode = EstimatorMode::PerChannel;
        std::string err;
        ASSERT_TRUE(parseEstimatorParams(e, {}, p, err)) << err;
        if (e.param("mode")) {
            EXPECT_EQ(p.mode, d.mode) << e.name;
        }
        if (e.param("threshold")) {
            EXPECT_EQ(p.giniThreshold, d.giniThreshold) << e.name;
        }
        if (e.param("alpha")) {
            EXPECT_EQ(p.alpha, d.alpha) << e.name;
        }
        if (e.param("gamma")) {
            EXPECT_EQ(p.gamma, d.gamma) << e.name;
        }
        if (e.param("delta")) {
            EXPECT_EQ(p.delta, d.delta) << e.name;
        }
        if (e.param("scale")) {
            EXPECT_EQ(p.scaleRelative, d.scaleRelative) << e.name;
        }
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
