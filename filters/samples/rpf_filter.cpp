// Random parameter filtering (Sen and Darabi 2011, implementation report; docs/rpf.md). Section
// and equation numbers below are the report's.
#include "mcstat/filters/samples/rpf_filter.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <mutex>

#include "mcstat/core/parallel.h"

// The per-pixel work, compiled twice: for AVX2 and for the baseline, chosen at load time by the
// CPU. The same arithmetic either way: no reassociation is allowed (no -ffast-math), and AVX2
// does not include FMA, so no multiply-add is contracted.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__SANITIZE_ADDRESS__)
#define MCSTAT_RPF_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define MCSTAT_RPF_CLONES
#endif

namespace mcstat {

namespace {

constexpr int kMaxBins = 256;  // per variable; a joint histogram is at most 256 x 256

/// splitmix64: one small, well-mixed generator per (seed, pass, pixel).
struct PixelRng {
    uint64_t state;
    PixelRng(uint64_t seed, int pass, uint64_t pixel)
        : state(seed ^ (uint64_t(pass + 1) * 0x9e3779b97f4a7c15ull) ^
                (pixel * 0xbf58476d1ce4e5b9ull)) {
        next();
        next();
    }
    uint64_t next() {
        uint64_t z = (state += 0x9e3779b97f4a7c15ull);
        z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
        z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
        return z ^ (z >> 31);
    }
    double uniform() { return double(next() >> 11) * 0x1.0p-53; }  // [0, 1)
};

/// c log c for integer counts and its increments, grown on demand (one per thread).
struct CLogC {
    std::vector<double> table{0.0};
    std::vector<double> step;  ///< step[c] = (c+1) log(c+1) - c log c
    void ensure(size_t n) {
        for (size_t c = table.size(); c <= n + 1; ++c)
            table.push_back(double(c) * std::log(double(c)));
        for (size_t c = step.size(); c <= n; ++c) step.push_back(table[c + 1] - table[c]);
    }
    double operator[](size_t c) const { return table[c]; }
};

/// Values binned by rounding after subtracting the minimum (section 5.1), with their entropy.
struct Binned {
    std::vector<uint8_t> bin;  // kMaxBins = 256
    int bins = 1;
    double entropy = 0;  ///< natural log
};

/// Values v[i * stride], i < n, binned; with `weight`, sample i counts weight[i] times and `total`
/// is the sum of the weights (a neighbourhood whose repeated draws are held once, section 4.1),
/// without, once (total = n). The histogram and entropy are those of the samples listed with
/// their repeats: the same integer counts, summed in the same order.
MCSTAT_RPF_CLONES
void binValues(const float* v, size_t stride, size_t n, const uint32_t* weight, size_t total,
               int maxBins, Binned& out, std::vector<uint32_t>& count, const CLogC& clogc) {
    out.bin.resize(n);
    float lo = std::numeric_limits<float>::infinity();
    for (size_t i = 0; i < n; ++i) lo = std::min(lo, v[i * stride]);
    const float top = float(maxBins - 1);
    int most = 0;
    for (size_t i = 0; i < n; ++i) {
        // v - lo + 0.5 >= 0.5, so truncation is floor: round to the nearest bin.
        const float d = std::min(v[i * stride] - lo + 0.5f, top);
        const int b = int(d);
        out.bin[i] = uint8_t(b);
        most = std::max(most, b);
    }
    out.bins = most + 1;
    // Four partial histograms, so that runs of one bin do not wait on each other's increments.
    const size_t nb = size_t(out.bins);
    count.assign(4 * nb, 0);
    size_t i4 = 0;
    if (weight) {
        for (; i4 + 4 <= n; i4 += 4)
            for (size_t l = 0; l < 4; ++l) count[l * nb + out.bin[i4 + l]] += weight[i4 + l];
        for (; i4 < n; ++i4) count[out.bin[i4]] += weight[i4];
    } else {
        for (; i4 + 4 <= n; i4 += 4)
            for (size_t l = 0; l < 4; ++l) ++count[l * nb + out.bin[i4 + l]];
        for (; i4 < n; ++i4) ++count[out.bin[i4]];
    }
    for (size_t b = 0; b < nb; ++b)
        count[b] += count[nb + b] + count[2 * nb + b] + count[3 * nb + b];
    count.resize(nb);
    // H = log n - (1/n) sum c log c
    double s = 0;
    for (uint32_t c : count) s += clogc[c];
    out.entropy = total > 0 ? std::log(double(total)) - s / double(total) : 0.0;
}

/// Eq. 1 from two binned vectors: H(X) + H(Y) - H(X, Y), clamped at 0 against rounding.
double binnedMutualInformation(const Binned& a, const Binned& b, size_t n,
                               std::vector<uint32_t>& joint, const CLogC& clogc) {
    if (a.bins == 1 || b.bins == 1 || n == 0) return 0.0;  // a constant tells nothing
    const size_t nb = size_t(b.bins), cells = size_t(a.bins) * nb;
    if (joint.size() < cells) joint.assign(cells, 0);
    // One pass: sum c log c grows by step[c] each time a bin's count c grows by one.
    double s = 0;
    const uint8_t* ab = a.bin.data();
    const uint8_t* bb = b.bin.data();
    for (size_t i = 0; i < n; ++i) s += clogc.step[joint[size_t(ab[i]) * nb + bb[i]]++];
    // Zero the table for the next pair: the cells when few, else only the occupied ones.
    if (cells <= 2 * n)
        std::fill_n(joint.begin(), cells, 0u);
    else
        for (size_t i = 0; i < n; ++i) joint[size_t(ab[i]) * nb + bb[i]] = 0;
    const double hxy = std::log(double(n)) - s / double(n);
    return std::max(0.0, a.entropy + b.entropy - hxy);
}

/// Eq. 1 of variable `a` with each of variables [b0, b1) (out[b - b0]), in one pass over the
/// samples: the joint histograms are independent, so their increments overlap in the CPU instead
/// of waiting on each other as one histogram's repeated cells would. Sample i counts weight[i]
/// times (binValues); `total` is the weights' sum.
MCSTAT_RPF_CLONES
void mutualInformationRange(const std::vector<Binned>& v, int a, int b0, int b1, size_t n,
                            const uint32_t* weight, size_t total, std::vector<uint32_t>& joint,
                            std::vector<size_t>& offsets, std::vector<int>& which,
                            const CLogC& clogc, double* out) {
    std::fill(out, out + (b1 - b0), 0.0);
    const Binned& x = v[size_t(a)];
    if (x.bins == 1 || n == 0) return;
    which.clear();
    offsets.clear();
    size_t cellsAll = 0;
    for (int b = b0; b < b1; ++b)
        if (b != a && v[size_t(b)].bins > 1) {
            which.push_back(b);
            offsets.push_back(cellsAll);
            cellsAll += size_t(x.bins) * size_t(v[size_t(b)].bins);
        }
    if (which.empty()) return;
    if (joint.size() < cellsAll) joint.assign(cellsAll, 0);
    const size_t m = which.size();
    const uint8_t* xa = x.bin.data();
    // Tables in groups of four per pass, their increments interleaved.
    for (size_t k0 = 0; k0 < m; k0 += 4) {
        const size_t g = std::min<size_t>(4, m - k0);
        uint32_t* t[4];
        const uint8_t* yb[4];
        size_t nb[4];
        for (size_t l = 0; l < 4; ++l) {
            const size_t k = k0 + std::min(l, g - 1);  // a short group repeats its last table
            t[l] = joint.data() + offsets[k];
            yb[l] = v[size_t(which[k])].bin.data();
            nb[l] = size_t(v[size_t(which[k])].bins);
        }
        if (g == 4) {
            for (size_t i = 0; i < n; ++i) {
                const size_t r = xa[i];
                const uint32_t c = weight[i];
                t[0][r * nb[0] + yb[0][i]] += c;
                t[1][r * nb[1] + yb[1][i]] += c;
                t[2][r * nb[2] + yb[2][i]] += c;
                t[3][r * nb[3] + yb[3][i]] += c;
            }
        } else {
            for (size_t l = 0; l < g; ++l)
                for (size_t i = 0; i < n; ++i) t[l][size_t(xa[i]) * nb[l] + yb[l][i]] += weight[i];
        }
    }
    const double logn = std::log(double(total));
    for (size_t k = 0; k < m; ++k) {
        const Binned& y = v[size_t(which[k])];
        const size_t cells = size_t(x.bins) * size_t(y.bins);
        uint32_t* t = joint.data() + offsets[k];
        double s = 0;
        // Either way the sum is the same for the samples with their repeats: the cells in order,
        // or the occupied cells in the order of their first sample (a repeat is never first).
        if (cells <= 2 * total) {
            for (size_t c = 0; c < cells; ++c) s += clogc[t[c]];
            std::fill_n(t, cells, 0u);
        } else {  // sparse: visit the occupied cells through the samples, clearing each once
            const size_t nb = size_t(y.bins);
            for (size_t i = 0; i < n; ++i) {
                uint32_t& c = t[size_t(xa[i]) * nb + y.bin[i]];
                s += clogc[c];
                c = 0;
            }
        }
        const double hxy = logn - s / double(total);
        out[which[k] - b0] = std::max(0.0, x.entropy + y.entropy - hxy);
    }
}

/// Everything one thread reuses from pixel to pixel.
struct Scratch {
    CLogC clogc;
    std::vector<Binned> binned;
    std::vector<uint32_t> count, joint;
    std::vector<size_t> offsets;
    std::vector<int> which;
    std::vector<double> mi;  // dims x dims, the pairs Algorithm 3 uses
    // N as drawn (Algorithm 2) lists a sample once per draw that picked it; it is held as its
    // distinct samples (`members`, in the order of their first draw, the pixel's own first) with
    // how many times each was drawn (`mult`), and the draws in order as indices into members
    // (`seq`, |N| entries). Counts are sums of multiplicities; sums of floating-point values run
    // over seq, in the order of the draws, so that every result is the same bit for bit as
    // with N listed in full.
    std::vector<size_t> members;  // N's distinct samples: indices into the window
    std::vector<uint32_t> mult;   // per member: how many draws of N picked it
    std::vector<uint32_t> seq;    // |N|: N's entries in draw order, as indices into members
    std::vector<uint32_t> ones;   // weights 1, for callers without repeats
    std::vector<float> xs;        // dims x members (by dimension), normalised (section 4.3)
    std::vector<float> cs;        // members x 3: the current colours c', normalised for eq. 18
    std::vector<float> z;         // k x members: the weighted coordinates of eq. 18, by dimension
    std::vector<float> color;     // 3 x members: the current colours c', by channel
    std::vector<float> d2;        // members: squared distances, then weights
    // The draws already seen for this pixel (Algorithm 2): per sample of the box, by its place in
    // the box's rows, the pixel's stamp and its member index (-1: failed the clustering test).
    std::vector<uint32_t> seenStamp;
    std::vector<int32_t> seenSlot;
    uint32_t stamp = 0;
    std::vector<int64_t> rowFirst;  // per box row: window index of its first sample in the box
    std::vector<int64_t> rowBase;   // per box row: place of that sample in the box's list
    std::vector<double> mean, sd, threshold;  // per feature: clustering (Algorithm 2)
    std::vector<double> dcfk;                 // 3 x features: eq. 6's terms
    std::vector<double> scale;                // per coordinate of eq. 18: its factor
    std::vector<int> source;                  // per coordinate of eq. 18: where it is read
    std::vector<double> aovMean;              // per AOV: its mean over the pixel (section 6.1)
};

/// The scratches of a pass's chunks: one per chunk running, kept from chunk to chunk so that a
/// thread does not grow a new one every few pixels. A scratch holds no result (a pixel's values do
/// not depend on which scratch served it, as with one thread serving every pixel).
class ScratchPool {
  public:
    std::unique_ptr<Scratch> take() {
        std::lock_guard<std::mutex> lock(mutex_);
        if (free_.empty()) return std::make_unique<Scratch>();
        std::unique_ptr<Scratch> s = std::move(free_.back());
        free_.pop_back();
        return s;
    }
    void give(std::unique_ptr<Scratch> s) {
        std::lock_guard<std::mutex> lock(mutex_);
        free_.push_back(std::move(s));
    }

  private:
    std::mutex mutex_;
    std::vector<std::unique_ptr<Scratch>> free_;
};

/// The law, per axis, of a neighbour's pixel offset: round(N(0, sigma_p^2)) with sigma_p = b/4
/// (Algorithm 2 line 1), as its cumulative distribution: cdf[0] = P(offset < -half),
/// cdf[1 + k] = P(offset <= k - half) for k in [0, 2 half]; beyond is outside the box.
struct OffsetLaw {
    static constexpr int kGuide = 1024;
    std::vector<double> cdf;
    std::vector<uint16_t> guide;  ///< guide[g]: the first index whose cdf exceeds g / kGuide
    explicit OffsetLaw(int b) {
        const int half = b / 2;
        const double sigma = b / 4.0;
        auto phi = [&](double v) { return 0.5 * std::erfc(-v / (sigma * std::sqrt(2.0))); };
        cdf.push_back(phi(-half - 0.5));
        for (int k = -half; k <= half; ++k) cdf.push_back(phi(k + 0.5));
        for (int g = 0; g < kGuide; ++g)
            guide.push_back(uint16_t(std::upper_bound(cdf.begin(), cdf.end(), double(g) / kGuide) -
                                     cdf.begin()));
    }
    /// The index of u in [0, 1): the first k with u < cdf[k], or cdf.size() (beyond the box).
    size_t find(double u) const {
        size_t k = guide[size_t(u * kGuide)];
        while (k < cdf.size() && !(u < cdf[k])) ++k;
        return k;
    }
};

/// exp(-x) for x >= 0 in float, vectorisable (the compiler cannot vectorise std::exp without
/// -ffast-math): 2^(-x log2 e) split into an integer power (exponent bits) and a degree-7
/// polynomial of 2^f on (-1, 0]: relative error below 5e-6 (measured). Zero below 2^-126.
inline float expNegative(float x) {
    const float t = std::min(x * 1.44269504f, 126.0f);  // -log2 of the result, in [0, 126]
    const int32_t n = int32_t(t);                       // t >= 0: truncation is floor
    const float f = float(n) - t;                       // in (-1, 0]
    // 2^f = e^(f ln 2) for f in (-1, 0]: its Taylor series to degree 7 (Horner).
    float p = 1.5252734e-5f;
    p = p * f + 1.5403530e-4f;
    p = p * f + 1.3333558e-3f;
    p = p * f + 9.6181291e-3f;
    p = p * f + 5.5504109e-2f;
    p = p * f + 2.4022651e-1f;
    p = p * f + 6.9314718e-1f;
    p = p * f + 1.0f;
    const int32_t bits = (127 - n) << 23;  // 2^-n
    float scale;
    std::memcpy(&scale, &bits, sizeof scale);
    return t < 126.0f ? p * scale : 0.0f;
}

/// Mean and (population) deviation of value(i), i < n, in double.
template <class Value>
void meanAndDeviationOf(Value value, size_t n, double& mean, double& sd) {
    // Four running sums, so the additions do not wait on each other (same result every run).
    double s[4] = {0, 0, 0, 0};
    size_t i = 0;
    for (; i + 4 <= n; i += 4)
        for (size_t l = 0; l < 4; ++l) s[l] += double(value(i + l));
    for (; i < n; ++i) s[0] += double(value(i));
    mean = n > 0 ? ((s[0] + s[1]) + (s[2] + s[3])) / double(n) : 0.0;
    double q[4] = {0, 0, 0, 0};
    for (i = 0; i + 4 <= n; i += 4)
        for (size_t l = 0; l < 4; ++l) {
            const double d = double(value(i + l)) - mean;
            q[l] += d * d;
        }
    for (; i < n; ++i) {
        const double d = double(value(i)) - mean;
        q[0] += d * d;
    }
    sd = n > 0 ? std::sqrt(((q[0] + q[1]) + (q[2] + q[3])) / double(n)) : 0.0;
}

void meanAndDeviation(const float* v, size_t stride, size_t n, double& mean, double& sd) {
    meanAndDeviationOf([&](size_t i) { return v[i * stride]; }, n, mean, sd);
}

/// Algorithm 3, eq. 1: the mutual information of every pair the weights use, into sc.mi (dims x
/// dims), over n distinct samples, sample i counting weight[i] times (total in all; weight null:
/// once each); dimension d of sample i is xs[d * dimStride + i * sampleStride] (samples by rows
/// or by columns).
void neighbourhoodDependencies(const RpfLayout& layout, const float* xs, size_t dimStride,
                               size_t sampleStride, size_t n, const uint32_t* weight, size_t total,
                               Scratch& sc) {
    const int dims = layout.dims(), nf = layout.features;
    const int fBase = 5 + layout.randoms;
    if (!weight) {
        sc.ones.assign(n, 1u);
        weight = sc.ones.data();
        total = n;
    }
    sc.clogc.ensure(total);
    sc.binned.resize(size_t(dims));
    for (int d = 0; d < dims; ++d)
        binValues(xs + size_t(d) * dimStride, sampleStride, n, weight, total, kMaxBins,
                  sc.binned[size_t(d)], sc.count, sc.clogc);
    // Every mutual information Algorithm 3 uses: colour channel k with all of p, r, f (dims
    // [3, dims)), feature k with p and r (dims [3, 5 + n)).
    sc.mi.assign(size_t(dims) * size_t(dims), 0.0);
    for (int k = 0; k < 3; ++k)
        mutualInformationRange(sc.binned, k, 3, dims, n, weight, total, sc.joint, sc.offsets,
                               sc.which, sc.clogc, sc.mi.data() + size_t(k) * size_t(dims) + 3);
    for (int k = 0; k < nf; ++k)
        mutualInformationRange(sc.binned, fBase + k, 3, fBase, n, weight, total, sc.joint,
                               sc.offsets, sc.which, sc.clogc,
                               sc.mi.data() + size_t(fBase + k) * size_t(dims) + 3);
}

/// Algorithm 3, eq. 2-16: the dependencies of sc.mi summed (eq. 2-8), their fractions due to the
/// random parameters (eq. 9-12), and the filter's weights alpha (eq. 15) and beta (eq. 16).
RpfWeights dependencyWeights(const RpfLayout& layout, int pass, double epsilon, Scratch& sc) {
    const int dims = layout.dims(), nr = layout.randoms, nf = layout.features;
    const int pBase = 3, rBase = 5, fBase = 5 + nr;
    auto mi = [&](int a, int b) { return sc.mi[size_t(a) * size_t(dims) + size_t(b)]; };
    RpfWeights w;
    const double grow = 1.0 + 0.1 * pass;  // the (1 + 0.1 t) of eq. 15 and 16
    double dcr = 0, dcp = 0, dcf = 0;
    std::vector<double>& dcfk = sc.dcfk;  // D_c,k^f,l, eq. 6 terms
    dcfk.assign(size_t(3 * nf), 0.0);
    for (int k = 0; k < 3; ++k) {
        double r = 0, p = 0, f = 0;
        for (int l = 0; l < nr; ++l) r += mi(k, rBase + l);  // eq. 4
        for (int l = 0; l < 2; ++l) p += mi(k, pBase + l);   // eq. 5
        for (int l = 0; l < nf; ++l) {                       // eq. 6
            dcfk[size_t(k * nf + l)] = mi(k, fBase + l);
            f += dcfk[size_t(k * nf + l)];
        }
        const double wcr = randomFraction(r, p, epsilon);  // eq. 10
        w.colorChannelOnRandom[size_t(k)] = wcr;
        w.alpha[size_t(k)] = std::max(1.0 - 2.0 * grow * wcr, 0.0);  // eq. 15
        dcr += r;
        dcp += p;
        dcf += f;  // eq. 8
    }
    w.colorOnRandom =
        (w.colorChannelOnRandom[0] + w.colorChannelOnRandom[1] + w.colorChannelOnRandom[2]) /
        3.0;  // eq. 11
    w.beta.assign(size_t(nf), 0.0);
    w.featureOnRandom.assign(size_t(nf), 0.0);
    w.colorOnFeature.assign(size_t(nf), 0.0);
    const double all = dcr + dcp + dcf;
    for (int k = 0; k < nf; ++k) {
        double r = 0, p = 0;
        for (int l = 0; l < nr; ++l) r += mi(fBase + k, rBase + l);  // eq. 2
        for (int l = 0; l < 2; ++l) p += mi(fBase + k, pBase + l);   // eq. 3
        const double dck =
            dcfk[size_t(k)] + dcfk[size_t(nf + k)] + dcfk[size_t(2 * nf + k)];  // eq. 7
        const double wfr = randomFraction(r, p, epsilon);                       // eq. 9
        const double wcf = all > 0 ? dck / all : 0.0;                           // eq. 12
        w.featureOnRandom[size_t(k)] = wfr;
        w.colorOnFeature[size_t(k)] = wcf;
        w.beta[size_t(k)] = wcf * std::max(1.0 - grow * wfr, 0.0);  // eq. 16
    }
    return w;
}

/// Algorithm 3 (eq. 1-16) over n distinct samples laid out as neighbourhoodDependencies reads
/// them, counted with their weights.
RpfWeights featureWeights(const RpfLayout& layout, const float* xs, size_t dimStride,
                          size_t sampleStride, size_t n, const uint32_t* weight, size_t total,
                          int pass, double epsilon, Scratch& sc) {
    neighbourhoodDependencies(layout, xs, dimStride, sampleStride, n, weight, total, sc);
    return dependencyWeights(layout, pass, epsilon, sc);
}

/// Algorithm 2 lines 2 and 7 (section 4.2): the mean and deviation of the pixel's features and,
/// per feature, how far from that mean a neighbour's feature may lie.
void clusterThresholds(const RpfWindow& w, const RpfParams& prm, size_t first, size_t s,
                       Scratch& sc) {
    const RpfLayout& L = w.layout;
    const int dims = L.dims(), fBase = 5 + L.randoms;
    sc.mean.assign(size_t(L.features), 0.0);
    sc.sd.assign(size_t(L.features), 0.0);
    for (int k = 0; k < L.features; ++k)
        meanAndDeviation(w.sample(first) + fBase + k, size_t(dims), s, sc.mean[size_t(k)],
                         sc.sd[size_t(k)]);
    // Line 7 as one threshold per feature: a neighbour is dropped when it lies more than 3 (world
    // positions: 30) pixel deviations from the pixel's mean, and beyond the 0.1 floor unless the
    // pixel itself varies more than 0.1.
    sc.threshold.resize(size_t(L.features));
    for (int k = 0; k < L.features; ++k) {
        const double sd = sc.sd[size_t(k)];
        const double limit =
            (L.isPosition[size_t(k)] ? prm.positionSigmas : prm.featureSigmas) * sd;
        sc.threshold[size_t(k)] = sd > prm.floor ? limit : std::max(limit, prm.floor);
    }
}

/// Algorithm 2's draws (section 4.1): `count` candidates drawn around pixel (x, y), each pixel
/// offset round(N(0, sigma_p^2)) per axis, one of that pixel's samples picked uniformly. The
/// candidates that land in the box, outside P, on a pixel with samples go to `batch` (returned:
/// how many) with their place in the box's samples (`place`, sc.rowFirst / rowBase), their
/// features prefetched: they lie at random places in a window of megabytes.
int drawCandidates(const RpfWindow& w, const OffsetLaw& law, int half, int x, int y, int64_t count,
                   PixelRng& rng, const Scratch& sc, size_t* batch, size_t* place) {
    const size_t featureOffset = size_t(5 + w.layout.randoms) * sizeof(float);
    const long last = long(law.cdf.size());
    int found = 0;
    for (int64_t q = 0; q < count; ++q) {
        // The offset per axis: round(N(0, sigma_p^2)) by inverting its law (section 4.1).
        const double ux = rng.uniform(), uy = rng.uniform(), pick = rng.uniform();
        const long ix = long(law.find(ux)), iy = long(law.find(uy));
        if (ix == 0 || ix == last || iy == 0 || iy == last) continue;  // outside the box
        const long ox = ix - 1 - half, oy = iy - 1 - half;
        if (ox == 0 && oy == 0) continue;  // inside P: its samples are in N already
        const long nx = x + ox, ny = y + oy;
        if (nx < 0 || nx >= w.width || ny < w.y0 || ny >= w.y0 + w.rows) continue;
        const size_t pq = size_t(ny - w.y0) * size_t(w.width) + size_t(nx);
        const size_t cnt = size_t(w.offset[pq + 1] - w.offset[pq]);
        if (cnt == 0) continue;
        const size_t j = size_t(w.offset[pq]) + std::min(cnt - 1, size_t(pick * double(cnt)));
        const char* at = reinterpret_cast<const char*>(w.sample(j)) + featureOffset;
        __builtin_prefetch(at);
        __builtin_prefetch(at + size_t(w.layout.features) * sizeof(float) - 1);
        const size_t row = size_t(oy + half);
        place[found] = size_t(int64_t(j) - sc.rowFirst[row] + sc.rowBase[row]);
        batch[found++] = j;
    }
    return found;
}

/// The samples of the box of pixel (x, y) (b x b pixels, clipped to the window) numbered row by
/// row: sc.rowFirst[r] is the window index of the first sample of box row r, sc.rowBase[r] its
/// number (the samples of a row of pixels are consecutive in the window). Returns how many.
size_t numberBoxSamples(const RpfWindow& w, int half, int x, int y, Scratch& sc) {
    const int b = 2 * half + 1;
    const long x0 = std::max(0, x - half), x1 = std::min(w.width - 1, x + half);
    sc.rowFirst.assign(size_t(b), 0);
    sc.rowBase.assign(size_t(b), 0);
    int64_t total = 0;
    for (int r = 0; r < b; ++r) {
        const long ny = y - half + r;
        if (ny < w.y0 || ny >= w.y0 + w.rows) continue;
        const size_t p0 = size_t(ny - w.y0) * size_t(w.width);
        const int64_t a = int64_t(w.offset[p0 + size_t(x0)]);
        sc.rowFirst[size_t(r)] = a;
        sc.rowBase[size_t(r)] = total;
        total += int64_t(w.offset[p0 + size_t(x1) + 1]) - a;
    }
    return size_t(total);
}

/// Algorithm 2 (sections 4.1-4.2): N <- P, then up to M - s neighbours (M of Algorithm 1 line 8)
/// drawn with a Gaussian of sigma_p = b/4 around the pixel, each kept when every feature is
/// within clusterThresholds' bound of the pixel's mean. A sample drawn again takes the first
/// draw's decision (the test depends on the sample alone) and is counted again (sc.mult, sc.seq).
void drawNeighbourhood(const RpfWindow& w, const RpfParams& prm, int pass, const OffsetLaw& law,
                       int x, int y, size_t first, size_t s, Scratch& sc) {
    const RpfLayout& L = w.layout;
    const int fBase = 5 + L.randoms;
    const int b = prm.boxes[size_t(pass)], half = b / 2;
    sc.members.clear();
    sc.mult.assign(s, 1u);
    sc.seq.clear();
    for (size_t i = 0; i < s; ++i) {
        sc.members.push_back(first + i);
        sc.seq.push_back(uint32_t(i));
    }
    const double M = std::min(std::floor(double(b) * double(b) * double(s) * prm.samplesFactor),
                              double(prm.maxNeighbourhood));
    const int64_t draws = std::max<int64_t>(0, int64_t(M) - int64_t(s));
    if (draws == 0) return;
    PixelRng rng(prm.seed, pass, uint64_t(y) * uint64_t(w.width) + uint64_t(x));
    const size_t boxSamples = numberBoxSamples(w, half, x, y, sc);
    if (sc.seenStamp.size() < boxSamples) {
        sc.seenStamp.resize(boxSamples, 0u);
        sc.seenSlot.resize(boxSamples, 0);
    }
    if (++sc.stamp == 0) {  // wrapped: no entry may look seen
        std::fill(sc.seenStamp.begin(), sc.seenStamp.end(), 0u);
        sc.stamp = 1;
    }
    // Candidates in batches: draw a batch (prefetching), then test them in draw order. The same
    // draws and the same decisions as one at a time.
    constexpr int kBatch = 32;
    size_t batch[kBatch], place[kBatch];
    const size_t cap = prm.maxKept > 0 ? size_t(prm.maxKept) : SIZE_MAX;
    for (int64_t q0 = 0; q0 < draws && sc.seq.size() < cap; q0 += kBatch) {
        const int64_t qn = std::min<int64_t>(kBatch, draws - q0);
        const int found = drawCandidates(w, law, half, x, y, qn, rng, sc, batch, place);
        for (int c = 0; c < found && sc.seq.size() < cap; ++c) {
            const size_t at = place[c];
            if (sc.seenStamp[at] == sc.stamp) {  // drawn before: the same decision
                const int32_t slot = sc.seenSlot[at];
                if (slot >= 0) {
                    ++sc.mult[size_t(slot)];
                    sc.seq.push_back(uint32_t(slot));
                }
                continue;
            }
            const float* f = w.sample(batch[c]) + fBase;
            bool keep = true;
            for (int k = 0; k < L.features; ++k)
                keep &= std::abs(double(f[k]) - sc.mean[size_t(k)]) <= sc.threshold[size_t(k)];
            sc.seenStamp[at] = sc.stamp;
            if (keep) {
                const uint32_t slot = uint32_t(sc.members.size());
                sc.seenSlot[at] = int32_t(slot);
                sc.members.push_back(batch[c]);
                sc.mult.push_back(1u);
                sc.seq.push_back(slot);
            } else {
                sc.seenSlot[at] = -1;
            }
        }
    }
}

/// Section 4.3: every element of the samples of N normalised over N (sc.xs, by dimension), and
/// their current colours c' likewise (sc.cs, by sample) for eq. 18. Means and deviations run
/// over N's draws in order (sc.seq), each distinct sample normalised once.
void normaliseNeighbourhood(const RpfWindow& w, const std::vector<float>& cIn, Scratch& sc) {
    const int dims = w.layout.dims();
    const size_t n = sc.members.size(), total = sc.seq.size();
    const uint32_t* seq = sc.seq.data();
    sc.xs.resize(n * size_t(dims));
    for (size_t i = 0; i < n; ++i) {
        const float* v = w.sample(sc.members[i]);
        for (int d = 0; d < dims; ++d) sc.xs[size_t(d) * n + i] = v[d];
    }
    for (int d = 0; d < dims; ++d) {
        float* v = sc.xs.data() + size_t(d) * n;
        double m, sd;
        meanAndDeviationOf([&](size_t i) { return v[seq[i]]; }, total, m, sd);
        const double inv = sd > 0 ? 1.0 / sd : 0.0;
        for (size_t i = 0; i < n; ++i) v[i] = float((double(v[i]) - m) * inv);
    }
    sc.cs.resize(n * 3);
    for (size_t i = 0; i < n; ++i)
        std::copy_n(cIn.data() + sc.members[i] * 3, 3, sc.cs.data() + i * 3);
    for (int d = 0; d < 3; ++d) {
        const float* c = sc.cs.data() + d;
        double m, sd;
        meanAndDeviationOf([&](size_t i) { return c[size_t(seq[i]) * 3]; }, total, m, sd);
        const double inv = sd > 0 ? 1.0 / sd : 0.0;
        for (size_t i = 0; i < n; ++i)
            sc.cs[i * 3 + size_t(d)] = float((double(sc.cs[i * 3 + size_t(d)]) - m) * inv);
    }
}

/// Fig. 6's intermediate values of the pixel: |N| and Algorithm 3's weights.
void reportPixel(size_t n, const RpfWeights& wt, RpfPixelReport& report) {
    report.neighbours = int(n);
    report.alpha = wt.alpha;
    report.beta = wt.beta;
    report.colorOnRandom = wt.colorOnRandom;
    report.featureOnRandom = wt.featureOnRandom;
}

/// Algorithm 4 lines 2-3 (eq. 19) and eq. 18 as one squared distance: sc.z holds coordinate k of
/// every sample of N scaled by sqrt(weight_k / (2 sigma^2)), by dimension (rows of |N|, so that
/// the loops over N run on contiguous floats), sc.color N's current colours by channel. Returns
/// the number of coordinates.
size_t bilateralCoordinates(const RpfWindow& w, const RpfParams& prm, const RpfWeights& wt,
                            size_t s, const std::vector<float>& cIn, Scratch& sc) {
    const int fBase = 5 + w.layout.randoms;
    const size_t n = sc.members.size();
    // sigma_c^2 = sigma_f^2 = sigma^2 / (1 - W_c^r)^2.
    const double sigma2 = 8.0 * prm.sigma8sq / double(s);
    const double keepShare = (1.0 - wt.colorOnRandom) * (1.0 - wt.colorOnRandom);
    sc.scale.clear();
    sc.source.clear();  // -1 - k: colour channel k; else the dims index
    for (int k = 0; k < 3; ++k)
        if (wt.alpha[size_t(k)] > 0 && keepShare > 0) {
            sc.scale.push_back(std::sqrt(wt.alpha[size_t(k)] * keepShare / (2.0 * sigma2)));
            sc.source.push_back(-1 - k);
        }
    for (int k = 0; k < w.layout.features; ++k)
        if (wt.beta[size_t(k)] > 0 && keepShare > 0) {
            sc.scale.push_back(std::sqrt(wt.beta[size_t(k)] * keepShare / (2.0 * sigma2)));
            sc.source.push_back(fBase + k);
        }
    const size_t kz = sc.scale.size();
    sc.z.resize(kz * n);
    for (size_t k = 0; k < kz; ++k) {
        const int src = sc.source[k];
        float* zk = sc.z.data() + k * n;
        for (size_t i = 0; i < n; ++i) {
            const float v = src < 0 ? sc.cs[i * 3 + size_t(-1 - src)] : sc.xs[size_t(src) * n + i];
            zk[i] = float(double(v) * sc.scale[k]);
        }
    }
    sc.color.resize(3 * n);
    for (size_t j = 0; j < n; ++j)
        for (size_t c = 0; c < 3; ++c) sc.color[c * n + j] = cIn[sc.members[j] * 3 + c];
    sc.d2.resize(n);
    return kz;
}

/// Eq. 18: sc.d2[j] <- w_ij, the weight of neighbour j for sample i of N, from the kz coordinates.
void bilateralWeights(size_t i, size_t kz, Scratch& sc) {
    const size_t n = sc.members.size();
    float* d2 = sc.d2.data();
    std::fill_n(d2, n, 0.f);
    for (size_t k = 0; k < kz; ++k) {
        const float* zk = sc.z.data() + k * n;
        const float zi = zk[i];
        for (size_t j = 0; j < n; ++j) {
            const float d = zi - zk[j];
            d2[j] += d * d;
        }
    }
    for (size_t j = 0; j < n; ++j) d2[j] = expNegative(d2[j]);  // w_ij
}

/// Eq. 20: the filtered colour c'' of a sample, N's current colours weighted by sc.d2 (in double),
/// summed over N's draws in order.
void filterColor(const Scratch& sc, float* out) {
    const size_t n = sc.members.size();
    const float* d2 = sc.d2.data();
    const float* r = sc.color.data();
    const float* g = r + n;
    const float* bl = g + n;
    double acc[3] = {0, 0, 0}, wsum = 0;
    for (const uint32_t j : sc.seq) {
        const double wij = d2[j];
        acc[0] += wij * r[j];
        acc[1] += wij * g[j];
        acc[2] += wij * bl[j];
        wsum += wij;
    }
    for (int c = 0; c < 3; ++c) out[c] = float(acc[c] / wsum);  // wsum >= w_ii = 1
}

/// The AOVs of a sample (docs/aovs.md) with eq. 20's weights sc.d2: a non-finite value is left
/// out of its channel, a label kept as it is.
void filterAovs(const RpfWindow& w, const float* aIn, const Scratch& sc, float* out) {
    const size_t A = w.aovs;
    for (size_t a = 0; a < A; ++a) {
        if (w.aovFixed[a]) continue;  // a label: kept as it is
        double av = 0, aw = 0;
        for (const uint32_t j : sc.seq) {
            const float v = aIn[sc.members[j] * A + a];
            if (!std::isfinite(v)) continue;
            av += double(sc.d2[j]) * double(v);
            aw += double(sc.d2[j]);
        }
        out[a] = aw > 0 ? float(av / aw) : 0.f;
    }
}

/// Section 6.1 (Algorithm 4 lines 13-20): a filtered sample of the pixel (samples [first,
/// first + s)) above the pixel's mean by more than one deviation becomes the mean, per channel;
/// the A AOVs that sum to that channel become their own means alike.
void removeSpikes(const RpfWindow& w, size_t first, size_t s, size_t A, std::vector<float>& cOut,
                  float* aOut, Scratch& sc) {
    // The AOVs' means over the pixel's samples before any spike is replaced.
    sc.aovMean.assign(A, 0.0);
    for (size_t a = 0; a < A; ++a) {
        for (size_t i = 0; i < s; ++i) sc.aovMean[a] += double(aOut[(first + i) * A + a]);
        sc.aovMean[a] /= double(s);
    }
    double mean[3] = {0, 0, 0}, sq[3] = {0, 0, 0};
    for (size_t i = 0; i < s; ++i)
        for (int c = 0; c < 3; ++c) mean[c] += double(cOut[(first + i) * 3 + size_t(c)]);
    for (int c = 0; c < 3; ++c) mean[c] /= double(s);
    for (size_t i = 0; i < s; ++i)
        for (int c = 0; c < 3; ++c) {
            const double d = double(cOut[(first + i) * 3 + size_t(c)]) - mean[c];
            sq[c] += d * d;
        }
    for (int c = 0; c < 3; ++c) {
        const double sd = std::sqrt(sq[c] / double(s));
        for (size_t i = 0; i < s; ++i) {
            float& v = cOut[(first + i) * 3 + size_t(c)];
            if (double(v) - mean[c] > sd) {
                v = float(mean[c]);
                for (size_t a = 0; a < A; ++a)  // the AOVs that sum to this channel, alike
                    if (w.aovFollows[a] == c) aOut[(first + i) * A + a] = float(sc.aovMean[a]);
            }
        }
    }
}

/// Algorithm 2, 3 and 4 (and section 6.1 when asked) for pixel (x, y): its samples' filtered
/// colours (and AOVs) into cOut (and aOut).
MCSTAT_RPF_CLONES
void filterPixel(const RpfWindow& w, const RpfParams& prm, int pass, const OffsetLaw& law, int x,
                 int y, const std::vector<float>& cIn, std::vector<float>& cOut, Scratch& sc,
                 RpfPixelReport* report, const float* aIn, float* aOut) {
    const size_t p = size_t(y - w.y0) * size_t(w.width) + size_t(x);
    const size_t first = size_t(w.offset[p]), s = size_t(w.offset[p + 1]) - first;
    if (s == 0) return;
    clusterThresholds(w, prm, first, s, sc);
    drawNeighbourhood(w, prm, pass, law, x, y, first, s, sc);
    normaliseNeighbourhood(w, cIn, sc);
    const size_t n = sc.members.size(), total = sc.seq.size();
    const RpfWeights wt = featureWeights(w.layout, sc.xs.data(), n, 1, n, sc.mult.data(), total,
                                         pass, prm.epsilon, sc);
    if (report) reportPixel(total, wt, *report);
    // Algorithm 4, eq. 18-20, for every sample of the pixel (the first s members of N).
    const size_t kz = bilateralCoordinates(w, prm, wt, s, cIn, sc);
    const size_t A = aIn ? w.aovs : 0;
    for (size_t i = 0; i < s; ++i) {
        bilateralWeights(i, kz, sc);
        filterColor(sc, cOut.data() + (first + i) * 3);
        if (A > 0) filterAovs(w, aIn, sc, aOut + (first + i) * A);
    }
    if (prm.spikes && s >= 2) removeSpikes(w, first, s, A, cOut, aOut, sc);
}

}  // namespace

double mutualInformation(const float* a, const float* b, size_t n, int maxBins) {
    CLogC clogc;
    clogc.ensure(n);
    Binned ba, bb;
    std::vector<uint32_t> count, joint;
    std::vector<size_t> offsets;
    std::vector<int> which;
    std::vector<double> mi;  // dims x dims, the pairs Algorithm 3 uses
    maxBins = std::clamp(maxBins, 1, 65535);
    binValues(a, 1, n, nullptr, n, maxBins, ba, count, clogc);
    binValues(b, 1, n, nullptr, n, maxBins, bb, count, clogc);
    return binnedMutualInformation(ba, bb, n, joint, clogc);
}

RpfWeights rpfFeatureWeights(const RpfLayout& layout, const float* xs, size_t n, int pass,
                             double epsilon) {
    Scratch sc;
    return featureWeights(layout, xs, 1, size_t(layout.dims()), n, nullptr, n, pass, epsilon, sc);
}

int rpfHalo(const RpfParams& params) {
    int h = 0;
    for (int b : params.boxes) h += b / 2;
    return h;
}

bool validateRpfParams(const RpfParams& p, std::string& err) {
    if (p.boxes.empty()) {
        err = "rpf: no box sizes";
        return false;
    }
    for (int b : p.boxes)
        if (b < 1 || b > 255) {
            err = "rpf: box sizes must be in [1, 255]";
            return false;
        }
    if (!(p.samplesFactor > 0 && p.samplesFactor <= 64) || p.maxNeighbourhood < 1 ||
        p.maxKept < 0 || !(p.sigma8sq > 0) || !std::isfinite(p.sigma8sq) ||
        !(p.featureSigmas >= 0) || !(p.positionSigmas >= 0) || !(p.floor >= 0) ||
        !(p.epsilon > 0)) {
        err = "rpf: parameters out of range";
        return false;
    }
    return true;
}

void rpfPass(const RpfWindow& w, const RpfParams& params, int pass, const std::vector<float>& cIn,
             std::vector<float>& cOut, int rowBegin, int rowEnd, int nthreads,
             std::vector<RpfPixelReport>* report, const std::function<void(int)>& rowDone,
             const std::vector<float>* aIn, std::vector<float>* aOut) {
    rowBegin = std::max(rowBegin, w.y0);
    rowEnd = std::min(rowEnd, w.y0 + w.rows);
    if (rowEnd <= rowBegin || w.width <= 0) return;
    if (report) report->assign(size_t(rowEnd - rowBegin) * size_t(w.width), RpfPixelReport());
    const OffsetLaw law(params.boxes[size_t(pass)]);
    const int64_t width = w.width, pixels = int64_t(rowEnd - rowBegin) * width;
    // Chunks of pixels, at most a row each and about 64 per thread: a small image has few rows
    // (48 at 64 x 48: 24 per thread on 2 cores, 3 on 16), and a pass lasts as long as its last
    // chunk. Every pixel depends on the input alone, so any cut gives the same bits.
    const int64_t chunk =
        std::clamp<int64_t>(pixels / (int64_t(threadCount(nthreads)) * 64), 1, width);
    ScratchPool scratches;
    std::mutex progressLock;
    std::vector<int64_t> left(rowDone ? size_t(rowEnd - rowBegin) : 0, width);  // per row
    parallelFor(0, pixels, chunk, nthreads, [&](int64_t b, int64_t e) {
        std::unique_ptr<Scratch> sc = scratches.take();
        for (int64_t i = b; i < e; ++i)
            filterPixel(w, params, pass, law, int(i % width), rowBegin + int(i / width), cIn, cOut,
                        *sc, report ? &(*report)[size_t(i)] : nullptr,
                        aIn && aOut ? aIn->data() : nullptr, aIn && aOut ? aOut->data() : nullptr);
        scratches.give(std::move(sc));
        if (!rowDone) return;
        std::lock_guard<std::mutex> lock(progressLock);  // a row is done when its last chunk is
        for (int64_t r = b / width; r <= (e - 1) / width; ++r) {
            left[size_t(r)] -= std::min(e, (r + 1) * width) - std::max(b, r * width);
            if (left[size_t(r)] == 0) rowDone(rowBegin + int(r));
        }
    });
}

void rpfFilterRows(const RpfWindow& w, const RpfParams& params, int outBegin, int outEnd,
                   std::vector<float>& rgb, int nthreads, const std::function<void(int)>& rowDone,
                   std::vector<RpfPixelReport>* firstPass, std::vector<float>* aovOut) {
    const int passes = int(params.boxes.size());
    // Rows each pass must filter so that the last pass has what it reads: pass t covers the
    // rows of pass t+1 widened by pass t+1's box/2, clipped to the image.
    std::vector<int> lo(static_cast<size_t>(passes)), hi(static_cast<size_t>(passes));
    lo[size_t(passes - 1)] = outBegin;
    hi[size_t(passes - 1)] = outEnd;
    for (int t = passes - 2; t >= 0; --t) {
        const int r = params.boxes[size_t(t + 1)] / 2;
        lo[size_t(t)] = std::max(0, lo[size_t(t + 1)] - r);
        hi[size_t(t)] = std::min(w.height, hi[size_t(t + 1)] + r);
    }
    std::vector<float> cur(w.samples() * 3), nxt;
    for (size_t i = 0; i < w.samples(); ++i) std::copy_n(w.sample(i), 3, cur.data() + i * 3);
    const size_t A = aovOut ? w.aovs : 0;
    std::vector<float> aCur, aNxt;
    if (A > 0) aCur = w.aov;
    for (int t = 0; t < passes; ++t) {
        nxt = cur;  // Algorithm 1 lines 14-16: c' <- c'' after the pass
        if (A > 0) aNxt = aCur;
        std::vector<RpfPixelReport> report;
        const bool want = t == 0 && firstPass != nullptr;
        rpfPass(w, params, t, cur, nxt, lo[size_t(t)], hi[size_t(t)], nthreads,
                want ? &report : nullptr, rowDone, A > 0 ? &aCur : nullptr,
                A > 0 ? &aNxt : nullptr);
        if (A > 0) aCur.swap(aNxt);
        if (want) {  // pass 0 covers [lo, hi], which holds the output rows
            const size_t skip = size_t(outBegin - std::max(lo[0], w.y0)) * size_t(w.width);
            firstPass->assign(report.begin() + std::ptrdiff_t(skip),
                              report.begin() + std::ptrdiff_t(skip + size_t(outEnd - outBegin) *
                                                                         size_t(w.width)));
        }
        cur.swap(nxt);
    }
    // Algorithm 1 line 19: box filter of each pixel's filtered samples (its own sums: rows on any
    // thread).
    rgb.assign(size_t(std::max(0, outEnd - outBegin)) * size_t(w.width) * 3, 0.f);
    parallelFor(outBegin, outEnd, 1, nthreads, [&](int64_t yb, int64_t ye) {
        for (int y = int(yb); y < int(ye); ++y)
            for (int x = 0; x < w.width; ++x) {
                const size_t p = size_t(y - w.y0) * size_t(w.width) + size_t(x);
                const size_t a = size_t(w.offset[p]), e = size_t(w.offset[p + 1]);
                if (e == a) continue;
                double s[3] = {0, 0, 0};
                for (size_t i = a; i < e; ++i)
                    for (int c = 0; c < 3; ++c) s[c] += double(cur[i * 3 + size_t(c)]);
                float* o = rgb.data() + (size_t(y - outBegin) * size_t(w.width) + size_t(x)) * 3;
                for (int c = 0; c < 3; ++c) o[c] = float(s[c] / double(e - a));
            }
    });
    if (A == 0) return;
    // The AOVs' box filter: the mean of the pixel's filtered samples (finite values), a label the
    // first sample's.
    aovOut->assign(size_t(std::max(0, outEnd - outBegin)) * size_t(w.width) * A, 0.f);
    parallelFor(outBegin, outEnd, 1, nthreads, [&](int64_t yb, int64_t ye) {
        for (int y = int(yb); y < int(ye); ++y)
            for (int x = 0; x < w.width; ++x) {
                const size_t p = size_t(y - w.y0) * size_t(w.width) + size_t(x);
                const size_t a0 = size_t(w.offset[p]), e = size_t(w.offset[p + 1]);
                if (e == a0) continue;
                float* o =
                    aovOut->data() + (size_t(y - outBegin) * size_t(w.width) + size_t(x)) * A;
                for (size_t k = 0; k < A; ++k) {
                    if (w.aovFixed[k]) {
                        o[k] = aCur[a0 * A + k];
                        continue;
                    }
                    double sum = 0;
                    size_t n = 0;
                    for (size_t i = a0; i < e; ++i)
                        if (std::isfinite(aCur[i * A + k])) {
                            sum += double(aCur[i * A + k]);
                            ++n;
                        }
                    o[k] = n ? float(sum / double(n)) : 0.f;
                }
            }
    });
}

}  // namespace mcstat
