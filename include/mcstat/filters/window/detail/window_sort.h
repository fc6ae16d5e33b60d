// The sorting and weight normalisation the weighted trimmed mean (window_rank.cpp) and the 3D
// filters' merge (filter3d.cpp) share. Private: mcstat::detail, not installed (cmake/Install.cmake
// leaves out every detail/ folder).
#pragma once

#include <vector>

#include "mcstat/filters/window/window_rank.h"

namespace mcstat {

namespace detail {
/// Sorts s.ranked ascending by key, ties by element index (the pair order).
void sortRanked(SpatialScratch& s);
/// Normalises recorded weights by their sum (the average's denominator).
void normaliseWeights(std::vector<SpatialScratch::WeightedElement>* rec, double wsum);
}  // namespace detail

}  // namespace mcstat
