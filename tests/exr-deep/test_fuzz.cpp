// Random corruption: flipped bytes and truncations at many deterministic positions. The reader must
// never crash; it either fails with a one-line message naming the file or returns valid data.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <random>

#include "mcstat/exr-deep/stats_file.h"
#include "sample_accumulator.h"
#include "test_support.h"

namespace mcstat::test {
namespace {

bool checkOutcome(const std::string& path, const std::string& what) {
    StatsImage img;
    std::string err;
    ReadLimits limits;
    limits.maxBytes = int64_t(64) << 20;  // keep a corrupted size from costing gigabytes
    const bool ok = readStatsFile(path, img, err, limits);
    if (ok) {
        std::string verr;
        EXPECT_TRUE(validateStats(img, path, verr)) << what << ": " << verr;
    } else {
        EXPECT_EQ(err.rfind(path + ": ", 0), 0u) << what << ": " << err;
        EXPECT_EQ(err.find('\n'), std::string::npos) << what << ": " << err;
    }
    StatsHeader hdr;
    (void)readStatsHeader(path, hdr, err, limits);
    return ok;
}

TEST(RandomCorruption, FlippedBytesAndTruncationsNeverCrash) {
    const StatsImage img = renderImage(17, 9, 3, 77, [](int x, int y) { return (x + 2 * y) % 7; });
    ScratchDir dir;
    const std::string good = dir.file("good.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(good, img, err)) << err;
    const std::vector<unsigned char> bytes = readBytes(good);
    const std::string path = dir.file("fuzz.mcstat");
    std::mt19937 rng(12345);
    int failures = 0, accepted = 0;
    // MCSTAT_FUZZ_ITERATIONS raises the count for a longer run (e.g. under the sanitizers).
    const char* env = std::getenv("MCSTAT_FUZZ_ITERATIONS");
    const int iterations = env != nullptr ? std::max(1, std::atoi(env)) : 400;
    for (int iter = 0; iter < iterations; ++iter) {
        std::vector<unsigned char> b = bytes;
        const int flips = 1 + int(rng() % 4);
        std::string what = "iter " + std::to_string(iter) + ":";
        for (int f = 0; f < flips; ++f) {
            // Half the flips hit the headers (first 12% of the file), where the structure lives.
            const size_t span = (rng() & 1) ? b.size() : b.size() / 8;
            const size_t pos = rng() % span;
            b[pos] ^= static_cast<unsigned char>(1u << (rng() % 8));
            what += " flip@" + std::to_string(pos);
        }
        if (iter % 5 == 0) {
            const size_t n = rng() % b.size();
            b.resize(n);
            what += " cut@" + std::to_string(n);
        }
        writeBytes(path, b);
        if (checkOutcome(path, what))
            ++accepted;
        else
            ++failures;
    }
    // Both outcomes occur: flips in pixel data of a float channel can leave a valid file.
    EXPECT_GT(failures, 0);
    RecordProperty("accepted", accepted);
}

}  // namespace
}  // namespace mcstat::test
