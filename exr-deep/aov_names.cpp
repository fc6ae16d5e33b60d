// AOV classes and names of the statistics file, version 5 (FORMAT.md "Version 5"; stats_file.h).
#include <string>

#include "mcstat/exr-deep/stats_file.h"

namespace mcstat {

const char* aovClassName(AovClass c) {
    switch (c) {
        case AovClass::Alpha:
            return "alpha";
        case AovClass::Light:
            return "light";
        case AovClass::Data:
            return "data";
        case AovClass::Id:
            return "id";
    }
    return "light";
}

bool parseAovClass(const std::string& text, AovClass& out) {
    for (AovClass c : {AovClass::Alpha, AovClass::Light, AovClass::Data, AovClass::Id})
        if (text == aovClassName(c)) {
            out = c;
            return true;
        }
    return false;
}

int StatsHeader::aovIndex(const std::string& name) const {
    for (size_t a = 0; a < aovs.size(); ++a)
        if (aovs[a].name == name) return int(a);
    return -1;
}

}  // namespace mcstat
