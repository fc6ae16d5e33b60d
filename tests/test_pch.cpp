// The owner of the test executables' shared precompiled header (tests/CMakeLists.txt): the
// header is built with this program's flags, and every mcstat_add_gtest target reuses it. The
// program itself does nothing and is not a test.
int main() { return 0; }
