/*
 * exr.h — internal entry points of exr.c: the reader on a file held in
 * memory (for the fuzzer) and the layer-to-channel naming of the writer.
 */
#ifndef HUSH_IO_EXR_H
#define HUSH_IO_EXR_H

#include "hush.h"

#include <stddef.h>
#include <stdint.h>

/* Room for any channel name hush writes: a layer name, '.', a letter. */
#define HUSH_EXR_NAME_MAX 72

/* Largest image hush_frame_read_exr() accepts: width * height. */
#define HUSH_EXR_MAX_PIXELS ((uint64_t)1 << 28)

/*
 * Reads an EXR held in memory; name stands for the file in messages.
 * max_pixels bounds width * height (0: HUSH_EXR_MAX_PIXELS), so a fuzzer
 * can keep allocations small. Same results and errors as
 * hush_frame_read_exr().
 */
hush_status hush__exr_read_memory(hush_device device, const char *name, const void *data,
                                  size_t size, uint64_t max_pixels, hush_frame *frame);

/*
 * The EXR channel that stores component comp of a layer with the given
 * channel count, as hush_frame_write_exr() names it (docs/sequence-format.md):
 * a 1-channel layer is its own name ("Z" for depth); "color" uses bare R, G,
 * B, A; normal and position use N.X.. and P.X..; motion uses motion.X..;
 * other layers name.R, name.G, name.B, name.A.
 */
void hush__exr_channel_name(const char *layer, int channels, int comp, char out[HUSH_EXR_NAME_MAX]);

#endif
