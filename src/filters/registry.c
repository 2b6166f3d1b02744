/*
 * registry.c — the filter classes this build provides, in listing order.
 * A new method adds its class object here.
 */
#include "filters/filter.h"

extern const hush_filter_class hush__filter_accumulate;
extern const hush_filter_class hush__filter_svgf;
extern const hush_filter_class hush__filter_asvgf;
extern const hush_filter_class hush__filter_taa;
extern const hush_filter_class hush__filter_bmfr;
extern const hush_filter_class hush__filter_nca;

const hush_filter_class *const hush__filter_classes[] = {
    &hush__filter_accumulate,
    &hush__filter_svgf,
    &hush__filter_asvgf,
    &hush__filter_taa,
    &hush__filter_bmfr,
    &hush__filter_nca,
};

const uint32_t hush__filter_class_count =
    (uint32_t)(sizeof hush__filter_classes / sizeof hush__filter_classes[0]);
