/*
 * sequence.h — a frame sequence on disk: a directory with one multi-channel
 * EXR per frame (frame_0000.exr, frame_0001.exr, ...) and cameras.json
 * (format "hush-cameras/1") with the per-frame matrices and jitter, the
 * resolution and the frame count. docs/sequence-format.md is the reference.
 */
#ifndef HUSH_IO_SEQUENCE_H
#define HUSH_IO_SEQUENCE_H

#include "hush.h"

#include <stddef.h>

typedef struct hush_camera {
  float world_to_view[16]; /* column-major, as in hush.h */
  float view_to_clip[16];
  float jitter[2];         /* pixels */
} hush_camera;

typedef struct hush_sequence {
  char *dir;               /* owned copy of the directory path */
  uint32_t width, height;
  uint32_t frame_count;
  char **files;            /* frame_count file names relative to dir, owned */
  hush_camera *cameras;    /* frame_count cameras, owned */
  hush_motion_source motion; /* what "motion" in the frames should be used for: "camera" or "vectors" */
} hush_sequence;

/*
 * Reads dir/cameras.json and checks it: format tag, positive resolution,
 * frame_count equal to the number of frame entries, 16 finite numbers per
 * matrix, 2 per jitter, a file name per frame that exists in dir. Errors name
 * the file and the field ("cameras.json: frames[3].world_to_view: expected
 * 16 numbers"). On success the caller owns *seq: hush__sequence_free() it.
 */
hush_status hush__sequence_read(hush_device device, const char *dir, hush_sequence *seq);
void hush__sequence_free(hush_sequence *seq);

/* Starts a sequence description for writing (owned by the caller): files
 * frame_0000.exr, frame_0001.exr, ... (malloc'd strings), identity matrices,
 * no jitter, CAMERA motion. Fill in the cameras, then write the frames and
 * hush__sequence_write_cameras(). */
hush_status hush__sequence_init(hush_device device, hush_sequence *seq, const char *dir,
                                uint32_t width, uint32_t height, uint32_t frame_count);

/* dir/files[i] into buf; HUSH_ERROR_INVALID_ARGUMENT if it does not fit. */
hush_status hush__sequence_frame_path(hush_device device, const hush_sequence *seq, uint32_t i,
                                      char *buf, size_t size);

/* Writes dir/cameras.json atomically (temp file + rename). */
hush_status hush__sequence_write_cameras(hush_device device, const hush_sequence *seq);

/* Fills a hush_frame_info for frame i: this and the previous camera (frame 0
 * uses its own as the previous one, with history RESET), motion source. */
void hush__sequence_frame_info(const hush_sequence *seq, uint32_t i, hush_frame_info *info);

/* Reads frame i (hush_frame_read_exr) and checks its size against the
 * sequence: "frame_0003.exr is 320x240, the sequence is 640x360". */
hush_status hush__sequence_read_frame(hush_device device, const hush_sequence *seq, uint32_t i,
                                      hush_frame *frame);

#endif
