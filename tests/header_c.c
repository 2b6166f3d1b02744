/* Compiles hush.h as plain C with -pedantic (the test is that this builds). */
#include "hush.h"
int hush_header_c_probe(void) { return (int)sizeof(hush_frame_info); }
