// The residual layers (appendResidual, imageops.h): plain mean - robust result, for the beauty and
// every AOV that holds light, so that a compositor can add back what an estimator removed.
#include <algorithm>

#include "mcstat/image/imageops.h"
#include "source_header.h"

namespace mcstat {

using OIIO::ImageBuf;
using OIIO::ImageSpec;
using OIIO::ROI;

using detail::headerOf;

namespace {

/// appendResidual over an image in memory or a streamed source.
template <class Source>
bool appendResidualTo(ImageBuf& robust, Source& src, const std::array<double, 3>& luma,
                      int nthreads) {
    const StatsHeader& h = headerOf(src);
    ImageBuf mean;
    if (!plainMean(mean, src, luma, robust.roi(), nthreads)) {
        robust.errorfmt("residual: {}", mean.geterror());
        return false;
    }
    const ImageSpec& rs = robust.spec();
    std::vector<int> meanIndex;
    const std::vector<int> from = residualChannels(rs, mean.spec(), h, meanIndex);
    std::vector<std::string> names;
    for (int c : from) names.push_back(kResidualPrefix + rs.channelnames[size_t(c)]);
    ImageSpec spec = rs;
    spec.nchannels = rs.nchannels + int(from.size());
    spec.channelnames.insert(spec.channelnames.end(), names.begin(), names.end());
    spec.channelformats.clear();
    ImageBuf out(spec);
    const ROI roi = robust.roi();
    const size_t nin = size_t(rs.nchannels), nout = size_t(spec.nchannels),
                 nm = size_t(mean.nchannels());
    const float* rp = static_cast<const float*>(robust.localpixels());
    const float* mp = static_cast<const float*>(mean.localpixels());
    float* op = static_cast<float*>(out.localpixels());
    for (size_t q = 0; q < roi.npixels(); ++q) {
        std::copy(rp + q * nin, rp + (q + 1) * nin, op + q * nout);
        for (size_t i = 0; i < from.size(); ++i)
            op[q * nout + nin + i] = float(double(mp[q * nm + size_t(meanIndex[i])]) -
                                           double(rp[q * nin + size_t(from[i])]));
    }
    robust = std::move(out);
    return true;
}

}  // namespace

std::vector<int> residualChannels(const ImageSpec& robust, const ImageSpec& mean,
                                  const StatsHeader& h, std::vector<int>& meanIndex) {
    std::vector<int> from;
    for (int c = 0; c < robust.nchannels; ++c) {
        const std::string& n = robust.channelnames[size_t(c)];
        const int a = h.aovIndex(n);
        if (c >= 3 && (a < 0 || h.aovs[size_t(a)].cls == AovClass::Id)) continue;
        const int m = mean.channelindex(n);
        if (m < 0) continue;
        from.push_back(c);
        meanIndex.push_back(m);
    }
    return from;
}

bool appendResidual(ImageBuf& robust, const StatsImage& src, const std::array<double, 3>& luma,
                    int nthreads) {
    return appendResidualTo(robust, src, luma, nthreads);
}

bool appendResidual(ImageBuf& robust, StatsBlockSource& src, const std::array<double, 3>& luma,
                    int nthreads) {
    return appendResidualTo(robust, src, luma, nthreads);
}

}  // namespace mcstat
