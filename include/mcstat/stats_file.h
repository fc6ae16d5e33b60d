// The mcstat statistics file, version 1: in-memory form, writer, reader, validator and merge.
// The on-disk layout is specified in exr-deep/FORMAT.md; this header is its C++ face.
// No function here throws: each returns false and fills `err` with a one-line message that names
// the file (when there is one) and the problem.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace mcstat {

/// File extension of statistics files (a single extension: OIIO picks readers by the last one).
inline constexpr const char* kStatsExtension = "mcstat";
/// Version of the layout written by this library (header attribute "mcstat:formatVersion").
inline constexpr int kStatsFormatVersion = 1;
/// Largest number of sub-buffers a file may declare (channel names use three digits).
inline constexpr int kMaxBuffers = 999;

/// Header data shared by every part of a statistics file.
struct StatsHeader {
    int formatVersion = kStatsFormatVersion;
    int width = 0, height = 0;     ///< data window size (pixels)
    int originX = 0, originY = 0;  ///< data window origin (OpenEXR dataWindow.min)
    int M = 1;                     ///< number of sub-buffers
    int64_t spp = 0;  ///< samples per pixel the producer aimed at (counts hold what was taken)
    std::string assignment = "roundrobin";  ///< sample-to-buffer rule, see FORMAT.md
    std::string renderer;                   ///< producer name and version
    std::string colorSpace = "lin_rec709";  ///< OCIO colour space name of every RGB value
    std::string seeds;  ///< comma-separated seeds of the renders merged into this file
};

/// Whole statistics file in memory. Pixel (x, y) of the data window has index p = y * width + x.
/// Every array is float32 as on disk; the producer accumulates in double and rounds once when
/// storing.
struct StatsImage {
    StatsHeader header;
    // part "beauty": the plain mean of every sample
    std::vector<float> beauty;  ///< [p*3 + c]
    // part "buffers": M sub-buffer means and their sample counts
    std::vector<float> bufferMean;   ///< [(p*M + j)*3 + c]
    std::vector<float> bufferCount;  ///< [p*M + j]
    // part "moments": Welford statistics over all samples
    std::vector<float> count;  ///< [p]   number of samples
    std::vector<float> mean;   ///< [p*3 + c]
    std::vector<float>
        variance;  ///< [p*3 + c] unbiased sample variance (n-1 denominator; 0 if n<2)
    // part "features": first-hit G-buffer features
    std::vector<float> normal;    ///< [p*3 + c] mean first-hit shading normal over hits
    std::vector<float> position;  ///< [p*3 + c] mean first-hit world position over hits
    std::vector<float> albedo;    ///< [p*3 + c] mean first-hit albedo over all samples (miss = 0)
    std::vector<float> depth;     ///< [p] mean first-hit distance over hits (+inf if none)
    std::vector<float> coverage;  ///< [p] fraction of samples whose camera ray hit geometry

    size_t pixelCount() const { return size_t(header.width) * size_t(header.height); }
    /// Allocates every array for header.width x header.height x header.M, zero-filled
    /// (depth filled with +inf). Returns false (and leaves *this untouched) on absurd sizes.
    bool allocate(std::string& err);
};

/// Limits for reading untrusted files, passed in (never global).
struct ReadLimits {
    int64_t maxPixels = int64_t(1) << 28;  ///< width * height
    int maxBuffers = kMaxBuffers;          ///< M
    int64_t maxBytes = int64_t(16) << 30;  ///< total bytes of pixel data to allocate
};

/// Writes `img` to `path` atomically: a temporary file in the same directory, renamed on success.
bool writeStatsFile(const std::string& path, const StatsImage& img, std::string& err);

/// Reads and validates a statistics file; allocation happens only after the headers pass
/// validation.
bool readStatsFile(const std::string& path, StatsImage& img, std::string& err,
                   const ReadLimits& limits = ReadLimits());

/// Reads only the headers (cheap): what `mcstat --info` shows before loading pixels.
bool readStatsHeader(const std::string& path, StatsHeader& hdr, std::string& err,
                     const ReadLimits& limits = ReadLimits());

/// Checks the in-memory invariants (sizes, counts finite, non-negative and integral, buffer counts
/// summing to the moments count). `what` names the source in the message.
bool validateStats(const StatsImage& img, const std::string& what, std::string& err);

/// Combines two renders of the same image (same size, M, assignment) into one, as if a single
/// render had taken all samples: per-buffer count-weighted sums, Chan's parallel variance.
bool mergeStats(const StatsImage& a, const StatsImage& b, StatsImage& out, std::string& err);

}  // namespace mcstat
