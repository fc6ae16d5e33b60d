// The window family's kernel (operation.h: WindowKernel): its parameters bound, and the passes that
// run it over an input, so that the image layer runs every window operation through one interface
// without naming MIF or the 3D filters. Jung, "Rendering of Teeth and Dental Restorations using
// Robust Statistical Estimation Techniques", PhD thesis, University of Minnesota, 2016, chapter 5.
#pragma once

#include "mcstat/filters/operation.h"
#include "mcstat/filters/window/window_rank.h"

namespace mcstat {

/// The kernel of a window operation over `over` with `params` bound: its halo from the window, its
/// mode, a `check` that validates `params` (validateSpatialParams) before any input is read, and
/// a `begin` that validates them again and prepares
/// - over an image (Neighbourhood::Image): WMIF / MIF at each output pixel (mif.h: wmifPixel);
/// - over sub-buffers (SubBuffers): the 3D filters, each pixel's buffers of the output rectangle
///   grown by the halo (clipped to the input) sorted once over nthreads threads, then every output
///   pixel merges its window's lists (filter3d.h: RankedBufferGrid, eq. 5.24).
/// Each output pixel equals wmifPixel's / filter3DPixel's for the whole input, bit for bit.
WindowKernel windowKernel(Neighbourhood over, const SpatialParams& params);

}  // namespace mcstat
