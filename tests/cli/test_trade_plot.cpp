// `mcstat --tradeplot TABLE` end to end (docs/trade.md): columns found by name in any order, the
// seeds of one method and spp averaged with their range, the reference's rows kept out of the
// curves, the points written as CSV and counted on the picture, and every refusal one line.
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>

#include <fstream>
#include <string>

#include "cli_support.h"

namespace {

using mcstat::testing::Result;

class TradePlotCli : public mcstat::testing::CliFixture {
  protected:
    void write(const std::string& name, const std::string& text) const {
        std::ofstream(path(name), std::ios::binary) << text;
    }
};

// Columns in another order than trade.sh writes them, with one it does not know.
const char* const kTable =
    "relMSE,method,scene,extra,seconds,spp,seed,bytesPerPixel,SSIM\n"
    "0.5,mean,a,x,0.2,16,1,10,0.50\n"
    "0.7,mean,a,x,0.4,16,2,10,0.60\n"
    "0.2,mean,a,x,0.8,64,1,10,0.70\n"
    "0.1,gmon,a,x,0.3,16,1,50,0.80\n"
    "0.3,gmon,a,x,0.5,16,2,50,0.90\n"
    "0.01,reference,a,x,0,4096,0,0,1\n"
    "9,mean,b,x,0.2,16,1,10,0.1\n";

TEST_F(TradePlotCli, SeedsAreAveragedPerMethodAndSppWithTheirRange) {
    write("t.csv", kTable);
    const Result r = mcstat("--tradeplot:scene=a:csv=" + path("p.csv") + " " + path("t.csv") +
                            " -o " + path("p.exr") + " -o " + path("p.png"));
    ASSERT_EQ(r.code, 0) << r.err;
    // Hand-computed: mean 16 spp = (0.5 + 0.7) / 2 at (0.2 + 0.4) / 2 s; gmon 16 spp likewise;
    // the reference is no curve; scene b is left out.
    EXPECT_EQ(mcstat::testing::slurp(path("p.csv")),
              "method,spp,seeds,x,y,yMin,yMax\n"
              "mean,16,2,0.30000000000000004,0.59999999999999998,0.5,0.69999999999999996\n"
              "mean,64,1,0.80000000000000004,0.20000000000000001,0.20000000000000001,"
              "0.20000000000000001\n"
              "gmon,16,2,0.40000000000000002,0.20000000000000001,0.10000000000000001,"
              "0.29999999999999999\n");
    OIIO::ImageBuf plot(path("p.exr"));
    ASSERT_TRUE(plot.read()) << plot.geterror();
    EXPECT_EQ(plot.spec().get_int_attribute("mcstat:tradeplot:points"), 3);
    EXPECT_GT(plot.spec().width, 500);
}

TEST_F(TradePlotCli, BytesAndSsimAxesAndTheChosenMethodsInTheirOrder) {
    write("t.csv", kTable);
    const Result r =
        mcstat("--tradeplot:scene=a:x=bytes:y=SSIM:methods=gmon,mean:csv=" + path("p.csv") + " " +
               path("t.csv") + " -o " + path("p.png"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(mcstat::testing::slurp(path("p.csv")),
              "method,spp,seeds,x,y,yMin,yMax\n"
              "gmon,16,2,50,0.85000000000000009,0.80000000000000004,0.90000000000000002\n"
              "mean,16,2,10,0.55000000000000004,0.5,0.59999999999999998\n"
              "mean,64,1,10,0.69999999999999996,0.69999999999999996,0.69999999999999996\n");
}

TEST_F(TradePlotCli, RefusalsAreOneLineNamingTheTable) {
    const std::string t = path("t.csv");
    const auto refused = [&](const std::string& table, const std::string& mods,
                             const std::string& want) {
        SCOPED_TRACE(mods + " " + want);
        write("t.csv", table);
        const Result r = mcstat("--tradeplot" + mods + " " + t + " -o " + path("p.png"));
        EXPECT_EQ(r.code, 1);
        EXPECT_NE(r.err.find(want), std::string::npos) << r.err;
        EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << r.err;
        EXPECT_TRUE(mcstat::testing::slurp(path("p.png")).empty());
    };
    refused(kTable, "", "holds 2 scenes ('a', 'b'): choose one with :scene=NAME");
    refused(kTable, ":scene=c", "has no rows of scene 'c' (scenes: 'a', 'b')");
    refused(kTable, ":scene=a:methods=mean,rpf", "has no rows of method 'rpf'");
    refused("method,spp,seconds\nmean,16,1\n", "", "no column relMSE");
    refused("method,spp,seconds,relMSE\nmean,16,1,x\n", "",
            "line 2: column relMSE: 'x' is not a finite number");
    refused("method,spp,seconds,relMSE\nmean,16,1,nan\n", "", "'nan' is not a finite number");
    refused("method,spp,seconds,relMSE\nmean,16,0,0.1\n", "",
            "line 2: column seconds must be positive");
    refused("method,spp,seconds,relMSE\nmean,16,1\n", "", "line 2 has 3 fields, the header 4");
    refused("method,spp,seconds,relMSE\n\"mean\",16,1,0.1\n", "", "line 2: quoted fields");
    refused("method,spp,seconds,relMSE\n", "", "no rows");
    refused(kTable, ":x=time", "x must be 'seconds' or 'bytes', not 'time'");
    const Result missing = mcstat("--tradeplot " + path("none.csv"));
    EXPECT_EQ(missing.code, 1);
    EXPECT_NE(missing.err.find("none.csv: no such file"), std::string::npos) << missing.err;
}

}  // namespace
