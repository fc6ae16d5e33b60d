// Pictures for review tools: contact sheet, heatmaps, quality-vs-spp plot (docs/review.md).
#include "cli.h"

namespace mcstat::cli {

void appendReviewCommands(std::vector<Command>&) {}

}  // namespace mcstat::cli
