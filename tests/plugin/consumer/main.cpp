// Calls G-MoN through an installed mcstat package, twice: directly on one hand-made pixel
// (mcstat::filters) and as an image operation on a 1x1 statistics image (mcstat::image, which
// pulls in mcstat::exrdeep, OpenImageIO and, for the luma weights, mcstat::color and OpenColorIO).
//
// Five buffers of 4 samples with grey means 1, 2, 1000, 3, 4. Sorted: 1 2 3 4 1000, Gini
// G = sum (2i - n - 1) x_i / (n sum x) = 4000 / 5050 = 0.792, k = floor(5/2) = 2,
// c = floor(k - (1 - G) k) = floor(1.58) = 1: one mean trimmed per side, estimate (2+3+4)/3 = 3.
#include <OpenImageIO/imagebuf.h>

#include <cstdio>
#include <string>

#include "mcstat/color/color.h"
#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"

int main() {
    const float grey[] = {1, 2, 1000, 3, 4};
    float mean[15];
    const float count[] = {4, 4, 4, 4, 4};
    for (int j = 0; j < 5; ++j) mean[j * 3] = mean[j * 3 + 1] = mean[j * 3 + 2] = grey[j];

    const mcstat::Operation* gmon = mcstat::findEstimator("gmon");
    if (!gmon) return 1;
    mcstat::PixelKernel kernel;
    std::string err;
    if (!mcstat::bindPixelKernel(*gmon, {}, mcstat::lumaCoefficients(), kernel, err)) return 1;
    mcstat::PixelBuffers px{mean, count, 5};
    mcstat::PixelEstimate out;
    mcstat::EstimatorScratch scratch;
    kernel.estimate(px, out, scratch);
    std::printf("%s pixel %.6f %.6f %.6f kept %d\n", gmon->title.c_str(), double(out.rgb[0]),
                double(out.rgb[1]), double(out.rgb[2]), out.kept[0]);

    mcstat::StatsImage img;
    img.header.width = img.header.height = 1;
    img.header.M = 5;
    if (!img.allocate(err)) {
        std::printf("allocate: %s\n", err.c_str());
        return 1;
    }
    img.bufferMean.assign(mean, mean + 15);
    img.bufferCount.assign(count, count + 5);
    OIIO::ImageBuf buf = mcstat::estimate(img, *gmon, kernel);
    float rgb[3] = {0, 0, 0};
    buf.getpixel(0, 0, rgb, 3);
    std::printf("%s image %.6f %.6f %.6f\n", gmon->title.c_str(), double(rgb[0]), double(rgb[1]),
                double(rgb[2]));
    return buf.has_error() ? 1 : 0;
}
