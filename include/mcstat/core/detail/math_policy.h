// The one Boost.Math error policy of mcstat's statistics: core's location statistics
// (location_stats.cpp) and the two-sample tests above it (analysis/two_sample.cpp). Boost.Math is
// header-only and reached privately: include this only from a .cpp of a library that links
// Boost::headers.
#pragma once

#include <boost/math/policies/policy.hpp>

namespace mcstat::detail {

// Boost.Math's default policy throws on domain errors and overflow; every argument reaching it is
// checked first (finite t, df > 0), and this policy makes any that slips through a NaN or a
// saturated value instead of an exception. By default Boost also computes a double in long double
// (x87, 4.4x slower here: 3.1 us against 0.71 us per tail, the whole cost of --compare's tests);
// double's own precision is what a p-value stored as float needs, and more.
using MathPolicy = boost::math::policies::policy<
    boost::math::policies::domain_error<boost::math::policies::ignore_error>,
    boost::math::policies::overflow_error<boost::math::policies::ignore_error>,
    boost::math::policies::evaluation_error<boost::math::policies::ignore_error>,
    boost::math::policies::rounding_error<boost::math::policies::ignore_error>,
    boost::math::policies::promote_double<false>>;

}  // namespace mcstat::detail
