// Channel naming: the beauty and the features are found by name in each renderer's convention.
#include <gtest/gtest.h>

#include "mcstat/ingest/channel_naming.h"
#include "render_files.h"

namespace mcstat {
namespace {

using testing::aovChannels;
using testing::cyclesChannels;
using testing::pbrtChannels;
using testing::pbrtOldChannels;

std::vector<std::string> namesAt(const std::vector<std::string>& names, std::array<int, 3> idx) {
    std::vector<std::string> out;
    for (int i : idx) out.push_back(i >= 0 ? names[size_t(i)] : "<none>");
    return out;
}

using Names = std::vector<std::string>;

TEST(ChannelNaming, PlainRGBWinsEvenAfterOtherLayers) {
    const Names names = {"AO.R", "AO.G", "AO.B", "B", "G", "R", "A"};
    BeautyChannels b;
    std::string problem;
    ASSERT_TRUE(findBeauty(names, "", b, problem)) << problem;
    EXPECT_EQ(namesAt(names, b.index), (Names{"R", "G", "B"}));
    EXPECT_EQ(b.layer, "");
    EXPECT_EQ(b.rule, "plain R,G,B");
}

TEST(ChannelNaming, CyclesCombinedNotTheAOLayerThatSortsFirst) {
    const Names names = cyclesChannels();
    ASSERT_EQ(names[0], "ViewLayer.AO.R");  // the trap: position 0..2 is AO
    BeautyChannels b;
    std::string problem;
    ASSERT_TRUE(findBeauty(names, "", b, problem)) << problem;
    EXPECT_EQ(namesAt(names, b.index),
              (Names{"ViewLayer.Combined.R", "ViewLayer.Combined.G", "ViewLayer.Combined.B"}));
    EXPECT_EQ(b.viewLayerPrefix, "ViewLayer.");
    const FeatureChannels f = findFeatures(names, b);
    EXPECT_EQ(namesAt(names, f.normal),
              (Names{"ViewLayer.Denoising Normal.X", "ViewLayer.Denoising Normal.Y",
                     "ViewLayer.Denoising Normal.Z"}));
    EXPECT_EQ(namesAt(names, f.albedo),
              (Names{"ViewLayer.Denoising Albedo.R", "ViewLayer.Denoising Albedo.G",
                     "ViewLayer.Denoising Albedo.B"}));
    ASSERT_GE(f.depth, 0);
    EXPECT_EQ(names[size_t(f.depth)], "ViewLayer.Denoising Depth.Z");
    EXPECT_EQ(f.present, unsigned(kFeatureNormal | kFeatureAlbedo | kFeatureDepth));
    EXPECT_EQ(namesAt(names, f.position), (Names{"<none>", "<none>", "<none>"}));
}

TEST(ChannelNaming, TwoViewLayersNeedALayer) {
    Names names = cyclesChannels("Day");
    for (const std::string& n : cyclesChannels("Night")) names.push_back(n);
    BeautyChannels b;
    std::string problem;
    EXPECT_FALSE(findBeauty(names, "", b, problem));
    EXPECT_NE(problem.find("several view layers have a Combined pass ('Day.Combined', "
                           "'Night.Combined'): choose one with :layer="),
              std::string::npos)
        << problem;
    ASSERT_TRUE(findBeauty(names, "Night.Combined", b, problem)) << problem;
    EXPECT_EQ(names[size_t(b.index[0])], "Night.Combined.R");
    // The features come from the chosen view layer, not the other one.
    const FeatureChannels f = findFeatures(names, b);
    EXPECT_EQ(names[size_t(f.normal[0])], "Night.Denoising Normal.X");
}

TEST(ChannelNaming, LayerGivenButMissingListsTheLayers) {
    const Names names = cyclesChannels();
    BeautyChannels b;
    std::string problem;
    EXPECT_FALSE(findBeauty(names, "ViewLayer.Diffuse", b, problem));
    EXPECT_NE(problem.find("no channels 'ViewLayer.Diffuse.R'"), std::string::npos) << problem;
    EXPECT_NE(problem.find("'ViewLayer.AO', 'ViewLayer.Combined'"), std::string::npos) << problem;
    // "." asks for the plain R, G, B, which a Cycles file has not.
    EXPECT_FALSE(findBeauty(names, ".", b, problem));
    EXPECT_NE(problem.find("no plain R, G, B"), std::string::npos) << problem;
}

TEST(ChannelNaming, PbrtV4GBufferFilm) {
    for (const Names& names : {pbrtChannels(), pbrtOldChannels()}) {
        BeautyChannels b;
        std::string problem;
        ASSERT_TRUE(findBeauty(names, "", b, problem)) << problem;
        EXPECT_EQ(namesAt(names, b.index), (Names{"R", "G", "B"}));
        const FeatureChannels f = findFeatures(names, b);
        // The shading normal Ns, not the geometric N: the features part holds shading normals.
        const bool dotted = names == pbrtChannels();
        EXPECT_EQ(namesAt(names, f.normal),
                  dotted ? (Names{"Ns.X", "Ns.Y", "Ns.Z"}) : (Names{"Nsx", "Nsy", "Nsz"}));
        EXPECT_EQ(namesAt(names, f.position),
                  dotted ? (Names{"P.X", "P.Y", "P.Z"}) : (Names{"Px", "Py", "Pz"}));
        EXPECT_EQ(namesAt(names, f.albedo), (Names{"Albedo.R", "Albedo.G", "Albedo.B"}));
        EXPECT_EQ(f.depth, -1);  // pbrt writes no depth
        EXPECT_EQ(f.present, unsigned(kFeatureNormal | kFeaturePosition | kFeatureAlbedo));
    }
}

TEST(ChannelNaming, AovLayersFindTheRGBABeauty) {
    const Names names = aovChannels();
    BeautyChannels b;
    std::string problem;
    ASSERT_TRUE(findBeauty(names, "", b, problem)) << problem;
    EXPECT_EQ(b.layer, "RGBA");
    EXPECT_EQ(namesAt(names, b.index), (Names{"RGBA.R", "RGBA.G", "RGBA.B"}));
    const FeatureChannels f = findFeatures(names, b);
    EXPECT_EQ(namesAt(names, f.normal), (Names{"N.X", "N.Y", "N.Z"}));
    EXPECT_EQ(namesAt(names, f.position), (Names{"P.X", "P.Y", "P.Z"}));
    EXPECT_EQ(names[size_t(f.depth)], "Z");
    EXPECT_EQ(f.present, unsigned(kFeatureNormal | kFeaturePosition | kFeatureDepth));
}

TEST(ChannelNaming, RenderManCiAndKarmaC) {
    BeautyChannels b;
    std::string problem;
    ASSERT_TRUE(findBeauty({"Nn.R", "Nn.G", "Nn.B", "Ci.R", "Ci.G", "Ci.B"}, "", b, problem));
    EXPECT_EQ(b.layer, "Ci");
    ASSERT_TRUE(
        findBeauty({"C.R", "C.G", "C.B", "albedo.R", "albedo.G", "albedo.B"}, "", b, problem));
    EXPECT_EQ(b.layer, "C");
}

TEST(ChannelNaming, TheOnlyRGBLayerIsTakenSeveralUnknownAreRefused) {
    BeautyChannels b;
    std::string problem;
    ASSERT_TRUE(findBeauty({"color.R", "color.G", "color.B", "depth.Z"}, "", b, problem));
    EXPECT_EQ(b.layer, "color");
    EXPECT_EQ(b.rule, "the only RGB layer");
    EXPECT_FALSE(
        findBeauty({"spec.R", "spec.G", "spec.B", "diff.R", "diff.G", "diff.B"}, "", b, problem));
    EXPECT_NE(problem.find("no recognisable beauty among the layers with R, G, B ('spec', "
                           "'diff')"),
              std::string::npos)
        << problem;
}

TEST(ChannelNaming, NoRGBAtAll) {
    BeautyChannels b;
    std::string problem;
    EXPECT_FALSE(findBeauty({"A", "Z", "R", "G"}, "", b, problem));
    EXPECT_NE(problem.find("no RGB channels"), std::string::npos) << problem;
    EXPECT_NE(problem.find("'A', 'Z', 'R', 'G'"), std::string::npos) << problem;
    EXPECT_FALSE(findBeauty({}, "", b, problem));
}

TEST(ChannelNaming, FeatureListText) {
    EXPECT_EQ(featureListText(kAllFeatures), "N,P,Albedo,Z,A");
    EXPECT_EQ(featureListText(kFeatureDepth | kFeatureNormal), "N,Z");
    EXPECT_EQ(featureListText(0), "");
    unsigned bits = 0;
    std::string problem;
    ASSERT_TRUE(parseFeatureList("Z,N", bits, problem));
    EXPECT_EQ(bits, unsigned(kFeatureDepth | kFeatureNormal));
    ASSERT_TRUE(parseFeatureList("", bits, problem));
    EXPECT_EQ(bits, 0u);
    EXPECT_FALSE(parseFeatureList("N,N", bits, problem));
    EXPECT_NE(problem.find("twice"), std::string::npos);
    EXPECT_FALSE(parseFeatureList("N,Velocity", bits, problem));
    EXPECT_NE(problem.find("unknown feature 'Velocity'"), std::string::npos);
    EXPECT_FALSE(parseFeatureList("N,", bits, problem));
}

}  // namespace
}  // namespace mcstat
