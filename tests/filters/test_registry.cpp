#include <gtest/gtest.h>

#include "mcstat/registry.h"

using namespace mcstat;

TEST(Registry, ListsTheFourEstimatorsOnce) {
    std::vector<std::string> names;
    for (const EstimatorInfo& e : estimatorRegistry()) {
        names.push_back(e.name);
        EXPECT_NE(e.fn, nullptr);
        EXPECT_FALSE(e.help.empty());
    }
    EXPECT_EQ(names, (std::vector<std::string>{"mean", "mon", "gmon", "gmonb"}));
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
