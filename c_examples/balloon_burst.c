/* balloon_burst: inflate a sphere until it cracks, print every topology change and write OBJ
 * frames.
 *   balloon_burst [frames_dir] [mesh.obj]     (defaults: balloon_frames, data/sphere.obj)
 * The balloon (time step 1/30 s) starts at rest and swells until its springs stretch by almost
 * the breaking strain; at step 12 a pin prick (a slit of two edges through one vertex, cut by
 * hand in one change with softshell_body_break_edges) opens the surface, the crack runs from
 * the slit's ends as each broken spring loads its neighbours, and the skin tears into pieces. Every 10th step and
 * every step that changes the topology is written as frames_dir/frame_NNNN.obj.
 * Exit status 0 on success, 1 on any error (the library's message is printed). */
#define _POSIX_C_SOURCE 200809L
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "softshell.h"

#define STEPS 30      /* at 1/30 s: the balloon settles in about 12 steps */
#define PRICK_STEP 12

static int fail(const char *what, SoftshellStatus status) {
  fprintf(stderr, "%s failed: %s: %s\n", what, softshell_status_name(status), softshell_last_error());
  return 1;
}

/* Buffers that grow when fracture adds vertices: re-queried after every topology change. */
typedef struct Buffers {
  float *positions;
  size_t positions_cap;
  uint32_t *triangles;
  size_t triangles_cap;
} Buffers;

/* Copies positions and triangles, growing the buffers when the library says they are too small. */
static SoftshellStatus fetch(const SoftshellBody *body, Buffers *b, size_t *n_floats, size_t *n_indices) {
  SoftshellStatus s = softshell_body_copy_positions(body, b->positions, b->positions_cap, n_floats);
  if (s == SOFTSHELL_STATUS_BUFFER_TOO_SMALL) {
    float *grown = realloc(b->positions, *n_floats * sizeof *grown);
    if (!grown) return SOFTSHELL_STATUS_INTERNAL;
    b->positions = grown;
    b->positions_cap = *n_floats;
    s = softshell_body_copy_positions(body, b->positions, b->positions_cap, n_floats);
  }
  if (s != SOFTSHELL_STATUS_OK) return s;
  s = softshell_body_copy_triangles(body, b->triangles, b->triangles_cap, n_indices);
  if (s == SOFTSHELL_STATUS_BUFFER_TOO_SMALL) {
    uint32_t *grown = realloc(b->triangles, *n_indices * sizeof *grown);
    if (!grown) return SOFTSHELL_STATUS_INTERNAL;
    b->triangles = grown;
    b->triangles_cap = *n_indices;
    s = softshell_body_copy_triangles(body, b->triangles, b->triangles_cap, n_indices);
  }
  return s;
}

static int write_obj(const char *dir, unsigned frame, const Buffers *b, size_t n_floats, size_t n_indices) {
  char path[4096];
  snprintf(path, sizeof path, "%s/frame_%04u.obj", dir, frame);
  FILE *f = fopen(path, "w");
  if (!f) {
    fprintf(stderr, "cannot write %s: %s\n", path, strerror(errno));
    return 1;
  }
  for (size_t i = 0; i + 2 < n_floats; i += 3)
    fprintf(f, "v %.6g %.6g %.6g\n", (double)b->positions[i], (double)b->positions[i + 1], (double)b->positions[i + 2]);
  for (size_t i = 0; i + 2 < n_indices; i += 3)
    fprintf(f, "f %u %u %u\n", (unsigned)b->triangles[i] + 1, (unsigned)b->triangles[i + 1] + 1,
            (unsigned)b->triangles[i + 2] + 1);
  /* A frame that could not be written is a failure (a full disk), not a frame. */
  if ((ferror(f) | fclose(f)) != 0) {
    fprintf(stderr, "writing %s failed: %s\n", path, strerror(errno));
    return 1;
  }
  return 0;
}

/* The two ends of a straight slit through vertex v: a neighbour of v and the one half way round
 * v's ring of neighbours (the ring walked from face to face around v). */
static void slit_ends(const uint32_t *triangles, size_t n_indices, uint32_t v, uint32_t ends[2]) {
  uint32_t ring[64];
  size_t count = 0;
  for (size_t t = 0; t + 2 < n_indices && count == 0; t += 3)
    for (int c = 0; c < 3; ++c)
      if (triangles[t + c] == v) {
        ring[count++] = triangles[t + (c + 1) % 3];
        break;
      }
  if (count == 0) { /* v is in no triangle: a slit of nothing */
    ends[0] = ends[1] = v;
    return;
  }
  /* Each face (v, a, b) in winding order leads from a to b: follow it until the ring closes. */
  while (count < 64) {
    uint32_t next = ring[0];
    for (size_t t = 0; t + 2 < n_indices; t += 3)
      for (int c = 0; c < 3; ++c)
        if (triangles[t + c] == v && triangles[t + (c + 1) % 3] == ring[count - 1]) next = triangles[t + (c + 2) % 3];
    if (next == ring[0]) break;
    ring[count++] = next;
  }
  ends[0] = ring[0];
  ends[1] = ring[count / 2];
}

int main(int argc, char **argv) {
  const char *dir = argc > 1 ? argv[1] : "balloon_frames";
  const char *path = argc > 2 ? argv[2] : "data/sphere.obj";
  if (mkdir(dir, 0777) != 0 && errno != EEXIST) {
    fprintf(stderr, "cannot create %s: %s\n", dir, strerror(errno));
    return 1;
  }

  SoftshellMesh *mesh = NULL;
  SoftshellStatus status = softshell_mesh_load_obj(path, &mesh);
  if (status != SOFTSHELL_STATUS_OK) return fail("softshell_mesh_load_obj", status);

  SoftshellBodyDef def = softshell_body_def_default();
  def.time_step = 1.0f / 30.0f;
  def.iterations = 4; /* at most 40 conjugate-gradient iterations per step: plenty here */
  def.total_mass = 1.0f;
  def.spring_stiffness = 400.0f;  /* N/m per edge */
  def.spring_damping = 1.0f;
  def.gas_amount = 700.0f;        /* nRT, J: inflated, the springs stretch by up to 11.4 % */
  def.break_strain = 0.125f;      /* springs stretched by 12.5 % crack */
  def.leak_rate = 0.5f;           /* the gas escapes through the holes */
  def.gravity[1] = 0.0f;

  SoftshellBody *body = NULL;
  status = softshell_body_new(mesh, &def, &body);
  softshell_mesh_free(mesh); /* the body keeps its own copy */
  if (status != SOFTSHELL_STATUS_OK) return fail("softshell_body_new", status);

  Buffers buffers = {NULL, 0, NULL, 0};
  size_t n_floats = 0, n_indices = 0;
  uint64_t generation = softshell_body_topology_generation(body);
  const uint64_t first_generation = generation;
  unsigned frame = 0;
  int result = 0;
  printf("%5s %8s %8s %9s %9s %10s\n", "step", "broken", "vertices", "triangles", "fragments", "pressure");
  for (unsigned step = 0; step < STEPS && result == 0; ++step) {
    if (step == PRICK_STEP && generation != first_generation) {
      /* Another mesh may burst under the gas alone before the prick: its edges are broken already. */
      printf("%5u: no pin prick, the balloon has burst already\n", step);
    } else if (step == PRICK_STEP) {
      /* A pin prick: a slit of two edges through the first triangle's first corner. */
      status = fetch(body, &buffers, &n_floats, &n_indices);
      if (status != SOFTSHELL_STATUS_OK) {
        result = fail("copying positions and triangles", status);
        break;
      }
      uint32_t ends[2];
      const uint32_t v = buffers.triangles[0];
      slit_ends(buffers.triangles, n_indices, v, ends);
      /* Both edges in one call: one topology change, and nothing cut if either were refused. */
      const uint32_t slit[4] = {ends[0], v, v, ends[1]};
      size_t broken = 0;
      status = softshell_body_break_edges(body, slit, 2, &broken);
      if (status != SOFTSHELL_STATUS_OK) {
        result = fail("softshell_body_break_edges", status);
        break;
      }
      if (broken != 2) {
        fprintf(stderr, "the slit broke %zu springs, not 2\n", broken);
        result = 1;
        break;
      }
      printf("%5u: pin prick, a slit %u-%u-%u cut by hand\n", step, (unsigned)ends[0], (unsigned)v, (unsigned)ends[1]);
      generation = softshell_body_topology_generation(body);
    }
    SoftshellBodyStats stats;
    status = softshell_body_step(body, &stats);
    if (status != SOFTSHELL_STATUS_OK) {
      result = fail("softshell_body_step", status);
      break;
    }
    int changed = stats.topology_generation != generation;
    if (changed) {
      generation = stats.topology_generation;
      printf("%5u %8llu %8zu %9zu %9zu %10.2f\n", step, (unsigned long long)stats.springs_broken,
             stats.vertex_count, stats.triangle_count, stats.fragment_count, stats.pressure);
    }
    if (changed || step % 10 == 0) {
      status = fetch(body, &buffers, &n_floats, &n_indices);
      if (status != SOFTSHELL_STATUS_OK) {
        result = fail("copying positions and triangles", status);
        break;
      }
      result = write_obj(dir, frame++, &buffers, n_floats, n_indices);
    }
    if (step == STEPS - 1)
      printf("final: volume %.4f m^3, pressure %.2f Pa, %zu fragments, %u frames in %s\n", stats.volume,
             stats.pressure, stats.fragment_count, frame, dir);
  }

  free(buffers.positions);
  free(buffers.triangles);
  softshell_body_free(body);
  return result;
}
