// printable(), oneLine(), isPrintable() and printableList() (core/untrusted_text.h): each escape
// by hand, the cut at a character boundary, and the property every caller relies on, that no
// output of printable() or oneLine() holds a byte a terminal acts on, over random bytes.
#include <gtest/gtest.h>

#include <random>
#include <string>

#include "mcstat/core/untrusted_text.h"

using mcstat::isPrintable;
using mcstat::libraryMessage;
using mcstat::oneLine;
using mcstat::printable;
using mcstat::printableList;

TEST(UntrustedText, PrintableTextStaysAsItIs) {
    EXPECT_EQ(printable("ViewLayer.Combined.R"), "ViewLayer.Combined.R");
    EXPECT_EQ(printable("Größe ☀ 𝄞 'quoted' ~"), "Größe ☀ 𝄞 'quoted' ~");  // 2-, 3-, 4-byte UTF-8
    EXPECT_EQ(printable(""), "");
    EXPECT_TRUE(isPrintable("Größe ☀ 𝄞"));
}

TEST(UntrustedText, ControlBytesBecomeVisibleEscapes) {
    EXPECT_EQ(printable("a\nb"), "a\\nb");
    EXPECT_EQ(printable("a\r\tb"), "a\\r\\tb");
    EXPECT_EQ(printable("\x1b[31mred"), "\\x1b[31mred");
    EXPECT_EQ(printable(std::string("a\0b", 3)), "a\\x00b");
    EXPECT_EQ(printable("\f\x07\x7f"), "\\x0c\\x07\\x7f");
    // The backslash is escaped too, so an escape in the output always means a byte in the input.
    EXPECT_EQ(printable("C:\\x1b"), "C:\\\\x1b");
}

TEST(UntrustedText, InvalidUtf8IsEscapedBytePerByte) {
    EXPECT_EQ(printable("\x80"), "\\x80");                             // a stray continuation byte
    EXPECT_EQ(printable("\xc0\xaf"), "\\xc0\\xaf");                    // an overlong '/'
    EXPECT_EQ(printable("\xe0\x80\xaf"), "\\xe0\\x80\\xaf");           // an overlong 3-byte form
    EXPECT_EQ(printable("\xed\xa0\x80"), "\\xed\\xa0\\x80");           // a UTF-16 surrogate
    EXPECT_EQ(printable("\xf4\x90\x80\x80"), "\\xf4\\x90\\x80\\x80");  // past U+10FFFF
    EXPECT_EQ(printable("\xe2\x82"), "\\xe2\\x82");                    // cut short at the end
    EXPECT_EQ(printable("\xe2\x82x"), "\\xe2\\x82x");                  // cut short by an ASCII byte
    EXPECT_EQ(printable("\xff\xfe"), "\\xff\\xfe");
    EXPECT_FALSE(isPrintable("\xc0\xaf"));
}

TEST(UntrustedText, HiddenUnicodeControlsAreEscaped) {
    EXPECT_EQ(printable("\xc2\x9b"
                        "31m"),
              "\\u{009b}31m");                      // C1 CSI
    EXPECT_EQ(printable("\xc2\x85"), "\\u{0085}");  // NEL
    EXPECT_EQ(printable("a\xe2\x80\xa8"
                        "b"),
              "a\\u{2028}b");  // line separator
    EXPECT_EQ(printable("abc\xe2\x80\xae"
                        "fdp.exe"),
              "abc\\u{202e}fdp.exe");  // RLO
    EXPECT_EQ(printable("\xe2\x81\xa6"), "\\u{2066}");
    EXPECT_EQ(printable("\xc2\xa0"), "\xc2\xa0");  // NBSP is a printable character
    EXPECT_FALSE(isPrintable("\xc2\x9b"));
    EXPECT_FALSE(isPrintable("\xe2\x80\xae"));
}

TEST(UntrustedText, LongStringsAreCutWithACount) {
    const std::string a300(300, 'a');
    EXPECT_EQ(printable(a300), std::string(200, 'a') + "... (100 more bytes)");
    EXPECT_EQ(printable(a300, 10), std::string(10, 'a') + "... (290 more bytes)");
    EXPECT_EQ(printable(a300, 0), a300);                                 // 0: never cut
    EXPECT_EQ(printable(std::string(200, 'a')), std::string(200, 'a'));  // exactly the limit
    // A cut inside a character keeps the whole character out: "é" is 2 bytes at 9..10.
    const std::string s = std::string(9, 'a') + "\xc3\xa9" + "bbb";
    EXPECT_EQ(printable(s, 10), std::string(9, 'a') + "... (5 more bytes)");
    EXPECT_EQ(printable(s, 11), std::string(9, 'a') + "\xc3\xa9... (3 more bytes)");
    // A 4-byte character cut after its first, second or third byte.
    const std::string clef = "xy\xf0\x9d\x84\x9ez";
    for (size_t cut = 3; cut <= 5; ++cut) EXPECT_EQ(printable(clef, cut), "xy... (5 more bytes)");
    EXPECT_EQ(printable(clef, 6), "xy\xf0\x9d\x84\x9e... (1 more byte)");
    // Invalid bytes are cut as bytes, each escaped.
    EXPECT_EQ(printable("\xff\xff\xff\xff", 2), "\\xff\\xff... (2 more bytes)");
}

TEST(UntrustedText, OneLineKeepsBackslashesAndCutsNothing) {
    EXPECT_EQ(oneLine("part '\\x1b[31m': bad\nsecond"), "part '\\x1b[31m': bad\\nsecond");
    EXPECT_EQ(oneLine(std::string(500, 'x')), std::string(500, 'x'));
    EXPECT_EQ(oneLine("\x1b[2J"), "\\x1b[2J");
}

TEST(UntrustedText, LibraryMessagesBecomeOneTrimmedLine) {
    EXPECT_EQ(libraryMessage("  Cannot read\nchannel 'a\x1b[31m'\r\n "),
              "Cannot read channel 'a\\x1b[31m'");
    EXPECT_EQ(libraryMessage("\n \n"), "");
    EXPECT_EQ(libraryMessage("C:\\dir"), "C:\\dir");  // the backslash stays, as in oneLine
}

TEST(UntrustedText, ListsAreQuotedEscapedAndBounded) {
    EXPECT_EQ(printableList({}), "none");
    EXPECT_EQ(printableList({"R", "G\nX"}), "'R', 'G\\nX'");
    EXPECT_EQ(printableList({"a", "b", "c"}, 2), "'a', 'b', ... (3 in all)");
}

TEST(UntrustedText, NewlinesAreAllowedOnlyBetweenLinesWhenAsked) {
    EXPECT_FALSE(isPrintable("a\nb"));
    EXPECT_TRUE(isPrintable("a\nb\n", true));
    EXPECT_FALSE(isPrintable("a\r\nb", true));
    EXPECT_FALSE(isPrintable("a\tb", true));
}

// The property: whatever bytes come in, what comes out holds nothing a terminal acts on, and
// printable() is the identity on text that is already printable and backslash-free.
TEST(UntrustedText, RandomBytesNeverSurviveUnescaped) {
    std::mt19937 rng(31);
    std::uniform_int_distribution<int> len(0, 40), byte(0, 255), pick(0, 3);
    // Bytes biased to the interesting ranges: controls, ASCII, UTF-8 leads and continuations.
    const auto draw = [&] {
        switch (pick(rng)) {
            case 0:
                return char(byte(rng) % 0x20);
            case 1:
                return char(0x20 + byte(rng) % 0x60);
            case 2:
                return char(0x80 + byte(rng) % 0x40);
            default:
                return char(0xc0 + byte(rng) % 0x40);
        }
    };
    for (int i = 0; i < 20000; ++i) {
        std::string s;
        for (int n = len(rng); n > 0; --n) s += draw();
        const std::string p = printable(s, size_t(len(rng)));
        ASSERT_TRUE(isPrintable(p)) << oneLine(s);
        ASSERT_TRUE(isPrintable(oneLine(s))) << oneLine(s);
        if (isPrintable(s) && s.find('\\') == std::string::npos) {
            ASSERT_EQ(printable(s, 0), s);
        }
    }
}
