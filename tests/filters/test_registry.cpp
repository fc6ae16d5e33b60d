#include <gtest/gtest.h>

#include "mcstat/registry.h"

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
