/* elastic_sheet: a FastLSM elastic sheet (softshell_lattice_*) pinned along two opposite edges,
 * poked in the middle, swinging back to rest.
 *   elastic_sheet OUTPUT_DIR [frames] [steps_per_frame]    (defaults: 90 frames, 2 steps each)
 * Writes OUTPUT_DIR/sheet_0000.obj, sheet_0001.obj, ... (the triangulated grid, one file per frame;
 * OUTPUT_DIR is created if missing) and prints per frame the mean and largest distance from the
 * particles to their shape-matching goals, the kinetic energy and the middle's height.
 * Exit status 0 on success, 1 on any error (the library's message is printed). */
#define _POSIX_C_SOURCE 200809L
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>

#include "softshell.h"

enum { COLUMNS = 24, ROWS = 16 };

static int fail(const char *what, SoftshellStatus status) {
  fprintf(stderr, "%s failed: %s: %s\n", what, softshell_status_name(status), softshell_last_error());
  return 1;
}

/* Writes positions and triangles (0-based in memory, 1-based in OBJ) to `path`. */
static int write_obj(const char *path, const float *positions, size_t float_count, const uint32_t *triangles,
                     size_t index_count) {
  FILE *file = fopen(path, "w");
  if (!file) {
    fprintf(stderr, "cannot write %s: %s\n", path, strerror(errno));
    return 1;
  }
  fprintf(file, "# softshell elastic_sheet frame\n");
  for (size_t i = 0; i + 2 < float_count; i += 3)
    fprintf(file, "v %.7g %.7g %.7g\n", (double)positions[i], (double)positions[i + 1], (double)positions[i + 2]);
  for (size_t i = 0; i + 2 < index_count; i += 3)
    fprintf(file, "f %u %u %u\n", (unsigned)triangles[i] + 1, (unsigned)triangles[i + 1] + 1,
            (unsigned)triangles[i + 2] + 1);
  if (fclose(file) != 0) {
    fprintf(stderr, "cannot finish %s: %s\n", path, strerror(errno));
    return 1;
  }
  return 0;
}

/* A whole number in [1, 1000000], all of `text`; 0 when it is not one. */
static int parse_count(const char *text, int *out) {
  char *end = NULL;
  errno = 0;
  long value = strtol(text, &end, 10);
  if (errno != 0 || end == text || *end != '\0' || value < 1 || value > 1000000) return 0;
  *out = (int)value;
  return 1;
}

int main(int argc, char **argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: %s OUTPUT_DIR [frames] [steps_per_frame]\n", argv[0]);
    return 1;
  }
  const char *dir = argv[1];
  int frames = 90, steps_per_frame = 2;
  if ((argc > 2 && !parse_count(argv[2], &frames)) || (argc > 3 && !parse_count(argv[3], &steps_per_frame))) {
    fprintf(stderr, "frames and steps_per_frame must be whole numbers from 1 to 1000000\n");
    return 1;
  }
  if (mkdir(dir, 0777) != 0 && errno != EEXIST) {
    fprintf(stderr, "cannot create %s: %s\n", dir, strerror(errno));
    return 1;
  }

  SoftshellLatticeDef def = softshell_lattice_def_default();
  def.columns = COLUMNS;
  def.rows = ROWS;
  def.spacing = 0.05f;          /* a 1.15 m x 0.75 m sheet */
  def.region_half_width = 4;    /* stiffer than the default 2 */
  def.stiffness = 0.8f;
  def.time_step = 1.0f / 60.0f;
  def.velocity_damping = 2.0f;  /* settles within a few seconds */

  SoftshellLattice *sheet = NULL;
  SoftshellStatus status = softshell_lattice_new(&def, NULL, &sheet);
  if (status != SOFTSHELL_STATUS_OK) return fail("softshell_lattice_new", status);

  /* Pin the two short edges (columns 0 and COLUMNS-1). */
  for (uint32_t row = 0; row < ROWS && status == SOFTSHELL_STATUS_OK; row++) {
    status = softshell_lattice_pin(sheet, 0, row);
    if (status == SOFTSHELL_STATUS_OK) status = softshell_lattice_pin(sheet, COLUMNS - 1, row);
  }
  if (status != SOFTSHELL_STATUS_OK) {
    softshell_lattice_free(sheet);
    return fail("softshell_lattice_pin", status);
  }

  /* Buffers: ask for the sizes first (a NULL buffer answers BUFFER_TOO_SMALL with the size). */
  size_t float_count = 0, index_count = 0, written = 0;
  if ((status = softshell_lattice_copy_positions(sheet, NULL, 0, &float_count)) != SOFTSHELL_STATUS_BUFFER_TOO_SMALL ||
      (status = softshell_lattice_copy_triangles(sheet, NULL, 0, &index_count)) != SOFTSHELL_STATUS_BUFFER_TOO_SMALL) {
    softshell_lattice_free(sheet);
    return fail("asking for the buffer sizes", status);
  }
  float *positions = (float *)malloc(float_count * sizeof *positions);
  uint32_t *triangles = (uint32_t *)malloc(index_count * sizeof *triangles);
  if (!positions || !triangles) {
    free(positions);
    free(triangles);
    softshell_lattice_free(sheet);
    fprintf(stderr, "out of memory\n");
    return 1;
  }
  status = softshell_lattice_copy_triangles(sheet, triangles, index_count, &written);

  uint32_t middle = 0;
  if (status == SOFTSHELL_STATUS_OK) status = softshell_lattice_particle_index(sheet, COLUMNS / 2, ROWS / 2, &middle);

  printf("elastic_sheet: %zu particles, %zu triangles, w = %u, %zu bytes, frames in %s\n",
         softshell_lattice_particle_count(sheet), softshell_lattice_triangle_count(sheet),
         (unsigned)def.region_half_width, softshell_lattice_memory_bytes(sheet), dir);
  printf("%5s %8s %14s %14s %14s %10s\n", "frame", "time s", "goal dist m", "max goal m", "kinetic J", "middle y");

  int result = 0;
  for (int frame = 0; frame < frames && status == SOFTSHELL_STATUS_OK; frame++) {
    SoftshellLatticeStats stats;
    memset(&stats, 0, sizeof stats);
    for (int s = 0; s < steps_per_frame && status == SOFTSHELL_STATUS_OK; s++) {
      /* The poke: a downward push on the middle particle during the first steps. */
      if (frame * steps_per_frame + s < 6) {
        const float push[3] = {0.0f, -1.5f, 0.0f};
        status = softshell_lattice_apply_force(sheet, COLUMNS / 2, ROWS / 2, push);
        if (status != SOFTSHELL_STATUS_OK) break;
      }
      status = softshell_lattice_step(sheet, &stats);
    }
    if (status != SOFTSHELL_STATUS_OK) break;
    status = softshell_lattice_copy_positions(sheet, positions, float_count, &written);
    if (status != SOFTSHELL_STATUS_OK) break;
    char path[4096];
    if (snprintf(path, sizeof path, "%s/sheet_%04d.obj", dir, frame) >= (int)sizeof path) {
      fprintf(stderr, "output path too long\n");
      result = 1;
      break;
    }
    if (write_obj(path, positions, written, triangles, index_count) != 0) {
      result = 1;
      break;
    }
    printf("%5d %8.3f %14.6e %14.6e %14.6e %10.5f\n", frame, stats.time, stats.goal_distance,
           stats.max_goal_distance, stats.kinetic_energy, (double)positions[3 * middle + 1]);
  }
  if (status != SOFTSHELL_STATUS_OK) result = fail("elastic_sheet step", status);

  free(positions);
  free(triangles);
  softshell_lattice_free(sheet);
  return result;
}
