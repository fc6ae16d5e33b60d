// Cascade reweighting (Zirr, Hanika and Dachsbacher 2018), the registry's per-sample operation
// "reweight" (filters/samples/cascade_reweighting_operation.cpp): the cascades built from the
// per-sample records, or read from the renderer's online state (state parts `cascades` flat,
// `cascades.deep` deep, owner "reweight": FORMAT.md "State parts with an owner"), then
// reweighted (cascade_reweighting.h). docs/reweighting.md.
#pragma once

#include <string>

#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/filters/operation.h"
#include "mcstat/filters/samples/cascade_reweighting.h"

namespace mcstat {

/// The registry name, which the state parts carry as their owner.
inline constexpr const char* kReweightName = "reweight";

/// The parameters from the registry entry's parsed values and the colour config's luma (unless
/// the values name one). False with one line naming the parameter.
bool reweightParamsFrom(const ParamValues& values, const std::array<double, 3>& luma,
                        ReweightParams& p, std::string& err);
/// The cascades' shape as the state parts' parameter text: "base=8:count=6:luma=...:start=1"
/// (kappa is not part of the state: it is chosen when reweighting).
std::string reweightStateText(const ReweightParams& p);

/// The state parts of cascades `img` built with `p`. False with one line when a count does not
/// fit (more than 2^32 - 1 samples).
bool encodeCascadeState(const CascadeImage& img, const std::vector<uint64_t>& skipped,
                        const ReweightParams& p, PixelStateParts& out, std::string& err);
/// The inverse, every value checked; `p` gets the stored count, base, start and luma.
bool decodeCascadeState(const PixelStateParts& parts, int width, CascadeImage& img,
                        std::vector<uint64_t>& skipped, ReweightParams& p, std::string& err);

/// SamplesFn of "reweight": R, G, B.
bool reweightSamples(const SamplesRequest& req, OperationImage& out, std::string& err);
/// The registry entry "reweight", with its state hooks.
Operation reweightOperation();

}  // namespace mcstat
