// Compiles hush.h as C++ (the test is that this file builds).
#include "hush.h"
int hush_header_cxx_probe() { return static_cast<int>(sizeof(hush_frame_info)); }
