// The base-layer check's fixture: each by-hand line below is caught; the comments and the string
// are not (M_PI, rename(, hardware_concurrency() named here are not code).
#include <cmath>
#include <filesystem>
#include <thread>

double radians(double deg) { return deg * M_PI / 180.0; }
double half_turn() { return 3.14159265358979; }
void commit(const std::filesystem::path& a, const std::filesystem::path& b) { std::filesystem::rename(a, b); }
unsigned cores() { return std::thread::hardware_concurrency(); }
const char* text() { return "M_PI and rename( in a string are fine"; }
