// `mcstat --plan` end to end: the table and the JSON carry the planner's numbers (thesis section
// 4.1.4 and 5.4.4), the command needs no input, and bad modifiers are one-line errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "cli_support.h"
#include "mcstat/analysis/planner.h"

using mcstat::testing::Result;
using mcstat::testing::runMcstat;

TEST(Plan, TableRecommendsTheThesisBufferCounts) {
    Result r = runMcstat("--plan");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("recommended M (smallest odd m, MPE alone): 17"), std::string::npos)
        << r.out;
    EXPECT_NE(r.out.find("1920 x 1080 = 2073600 pixels"), std::string::npos) << r.out;
    // 1080p needs P < 4.8e-7: MPE(7)+MIF(3x3) = 1.3e-8 is enough
    EXPECT_NE(r.out.find("m = 7: MPE+MIF 3x3, 3DMF 3x3"), std::string::npos) << r.out;
    // 1e8 pixels (section 4.1.4 and 5.3.1's 100M-pixel requirement): 19 buffers; windows of 5.3.1
    r = runMcstat("--plan:width=10000:height=10000");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("MPE alone): 19"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("m = 5: MPE+MIF 5x5, 3DMF 5x5"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("m = 7: MPE+MIF 5x5, 3DMF 3x3"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("m = 3: MPE+MIF 11x11, 3DMF 11x11"), std::string::npos) << r.out;
}

TEST(Plan, JsonCarriesThePlannerNumbers) {
    Result r = runMcstat("--plan:np=1:width=1000:height=1000:json=1:m=7:maxk=5");
    ASSERT_EQ(r.code, 0) << r.err;
    const nlohmann::json j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j["recommendedM"], 17);
    EXPECT_EQ(j["pixels"], 1e6);
    // MPE(15), MPE(17): entries 7 and 8 of m = 1, 3, ...
    EXPECT_EQ(j["mpe"][7]["m"], 15);
    EXPECT_NEAR(double(j["mpe"][7]["rate"]["p"]), 1.6389587393393117e-06, 1e-11);
    EXPECT_NEAR(double(j["mpe"][8]["rate"]["p"]), 1.3278544938458742e-07, 1e-12);
    // MPE(7)+MIF(3x3) = 1.3e-8 (section 5.4.4): the hybrid row m = 7, k = 3
    bool found = false;
    for (const auto& h : j["hybrids"]) {
        if (h["m"] == 7 && h["k"] == 3) {
            found = true;
            EXPECT_NEAR(double(h["mpeMif"]["p"]), 1.312079052220177e-08, 1e-13);
            EXPECT_NEAR(double(h["mpeMif"]["log10p"]), std::log10(1.312079052220177e-08), 1e-5);
        }
    }
    EXPECT_TRUE(found) << r.out;
    EXPECT_EQ(j["smallestWindows"][0]["mpeMif"], 3);  // 1.3e-8 < 1e-6
    EXPECT_EQ(j["smallestWindows"][0]["dmf3"], 3);
    EXPECT_EQ(j["smallestMifWindow"], 0);  // N p = 1 >= 0.5: MIF alone cannot (eq. 5.11)
    ASSERT_GE(j["minimumSpp"]["designs"].size(), 1u);
    EXPECT_EQ(j["minimumSpp"]["designs"][0]["design"], "MPE(17)");
    EXPECT_TRUE(j["minimumSpp"]["designs"][0]["feasible"]);
    // the same as the library
    const auto s = mcstat::planner::minimumSpp({mcstat::planner::Method::MPE, 17, 1}, 1e-3, 0.99);
    EXPECT_NEAR(double(j["minimumSpp"]["designs"][0]["sppExact"]), s.sppExact, 1e-6 * s.sppExact);
}

TEST(Plan, TinyProbabilitiesPrintAsPowersOfTen) {
    Result r = runMcstat("--plan:np=1e-200:json=1:maxm=5:m=3:maxk=3");
    ASSERT_EQ(r.code, 0) << r.err;
    const nlohmann::json j = nlohmann::json::parse(r.out);
    EXPECT_NEAR(double(j["mpe"][0]["rate"]["log10p"]), -200.0, 1e-9);
    EXPECT_NEAR(double(j["mpe"][1]["rate"]["log10p"]), -400.0 - std::log10(3.0), 1e-6);
    EXPECT_EQ(double(j["mpe"][1]["rate"]["p"]), 0.0);  // below the double range: log10 carries it
    Result t = runMcstat("--plan:np=1e-200:maxm=5:m=3:maxk=3");
    ASSERT_EQ(t.code, 0) << t.err;
    EXPECT_NE(t.out.find("10^-400.5"), std::string::npos) << t.out;
}

TEST(Plan, BadModifiersAreOneLineErrors) {
    struct Case {
        std::string args, needle;
    } cases[] = {
        {"--plan:np=0", "np must be"},
        {"--plan:np=abc", "np must be"},
        {"--plan:maxm=4", "maxm must be an odd integer"},
        {"--plan:m=3,x", "m must be an odd integer"},
        {"--plan:certainty=1", "certainty must be below 1"},
        {"--plan:json=yes", "json must be 0 or 1"},
        {"--plan:bogus=1", "no modifier 'bogus'"},
    };
    for (const Case& c : cases) {
        Result r = runMcstat(c.args);
        EXPECT_NE(r.code, 0) << c.args;
        EXPECT_NE(r.err.find(c.needle), std::string::npos) << c.args << " -> " << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        EXPECT_TRUE(r.out.empty()) << r.out;
    }
}
