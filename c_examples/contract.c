/* contract: squeeze a closed mesh with outside air pressure until it has shrunk (the README demo).
 *
 *   contract [-o DIR] [-n STEPS] [-r RATIO] [-e EVERY] [-t THREADS] [-p PRESSURE] [mesh.obj]
 *
 *   mesh.obj     closed, consistently oriented mesh (default data/kitten.obj); it is scaled to a
 *                unit bounding-box diagonal, the size the default settings are made for
 *   -o DIR       write DIR/frame_NNNNN.obj every EVERY steps and DIR/contract.csv (DIR is created)
 *   -n STEPS     stop after this many steps (default 300)
 *   -r RATIO     stop when the volume ratio V/V0 falls below RATIO (default 0.5)
 *   -e EVERY     frame and table interval in steps (default 10)
 *   -t THREADS   worker threads, 0 = all cores (default 1)
 *   -p PRESSURE  outside pressure in Pa, negative inflates (default: the library's)
 *   -c 0|1       self-collision off (default) or on
 *
 * Exit status 0 on success, 1 on any error (the library's message is printed). */
#define _POSIX_C_SOURCE 200809L
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "softshell.h"

static int fail(const char *what, SoftshellStatus status) {
  fprintf(stderr, "%s failed: %s: %s\n", what, softshell_status_name(status), softshell_last_error());
  return 1;
}

static int usage(const char *argv0) {
  fprintf(stderr, "usage: %s [-o DIR] [-n STEPS] [-r RATIO] [-e EVERY] [-t THREADS] [-p PRESSURE] [-c 0|1] [mesh.obj]\n",
          argv0);
  return 1;
}

/* A whole number >= minimum, all of `text`; 0 when it is not one. */
static int parse_count(const char *text, unsigned long minimum, unsigned long *out) {
  char *end = NULL;
  errno = 0;
  unsigned long value = strtoul(text, &end, 10);
  if (errno != 0 || end == text || *end != '\0' || text[0] == '-' || value < minimum) return 0;
  *out = value;
  return 1;
}

/* A number, all of `text` (NaN and infinities are passed on: the library says what it accepts). */
static int parse_number(const char *text, double *out) {
  char *end = NULL;
  double value = strtod(text, &end);
  if (end == text || *end != '\0') return 0;
  *out = value;
  return 1;
}

/* Writes the shell's current positions with the mesh's triangles as DIR/frame_NNNNN.obj. */
static SoftshellStatus write_frame(const char *dir, unsigned long step, const float *positions, size_t vertex_count,
                                   const uint32_t *triangles, size_t triangle_count) {
  char path[4096];
  snprintf(path, sizeof path, "%s/frame_%05lu.obj", dir, step);
  SoftshellMesh *frame = NULL;
  SoftshellStatus status = softshell_mesh_from_arrays(positions, vertex_count, triangles, triangle_count, &frame);
  if (status != SOFTSHELL_STATUS_OK) return status;
  status = softshell_mesh_save_obj(frame, path);
  softshell_mesh_free(frame);
  return status;
}

int main(int argc, char **argv) {
  const char *path = "data/kitten.obj";
  const char *dir = NULL;
  unsigned long max_steps = 300, every = 10, threads = 1, collisions = 0;
  double stop_ratio = 0.5;
  double pressure = 0.0;
  int pressure_given = 0;
  for (int i = 1; i < argc; i++) {
    if (argv[i][0] == '-' && argv[i][1] != '\0' && argv[i][2] == '\0') {
      if (i + 1 >= argc) return usage(argv[0]);
      const char *value = argv[++i];
      int ok = 1;
      switch (argv[i - 1][1]) {
        case 'o': dir = value; break;
        case 'n': ok = parse_count(value, 1, &max_steps); break;
        case 'r': ok = parse_number(value, &stop_ratio); break;
        case 'e': ok = parse_count(value, 1, &every); break;
        case 't': ok = parse_count(value, 0, &threads) && threads <= 0xFFFFFFFFul; break;
        case 'p': ok = pressure_given = parse_number(value, &pressure); break;
        case 'c': ok = parse_count(value, 0, &collisions) && collisions <= 1; break;
        default: return usage(argv[0]);
      }
      if (!ok) {
        fprintf(stderr, "%s: bad value '%s' for %s\n", argv[0], value, argv[i - 1]);
        return usage(argv[0]);
      }
    } else {
      path = argv[i];
    }
  }

  /* Load, then scale to a unit bounding-box diagonal about the box centre. */
  SoftshellMesh *loaded = NULL;
  SoftshellStatus status = softshell_mesh_load_obj(path, &loaded);
  if (status != SOFTSHELL_STATUS_OK) return fail("softshell_mesh_load_obj", status);
  size_t vertex_count = softshell_mesh_vertex_count(loaded), triangle_count = softshell_mesh_triangle_count(loaded);
  float *positions = (float *)malloc(3 * vertex_count * sizeof *positions);
  uint32_t *triangles = (uint32_t *)malloc(3 * triangle_count * sizeof *triangles);
  SoftshellMesh *mesh = NULL;
  SoftshellShell *shell = NULL;
  FILE *csv = NULL;
  int code = 1;
  size_t len = 0;
  if (!positions || !triangles) {
    fprintf(stderr, "out of memory\n");
    goto done;
  }
  if ((status = softshell_mesh_copy_positions(loaded, positions, 3 * vertex_count, &len)) != SOFTSHELL_STATUS_OK ||
      (status = softshell_mesh_copy_triangles(loaded, triangles, 3 * triangle_count, &len)) != SOFTSHELL_STATUS_OK) {
    code = fail("copying the mesh", status);
    goto done;
  }
  SoftshellMeshReport report;
  if ((status = softshell_mesh_report(loaded, &report)) != SOFTSHELL_STATUS_OK) {
    code = fail("softshell_mesh_report", status);
    goto done;
  }
  double diagonal = 0.0;
  for (int k = 0; k < 3; k++) diagonal += (double)(report.bbox_max[k] - report.bbox_min[k]) * (report.bbox_max[k] - report.bbox_min[k]);
  if (!(diagonal > 0.0)) {
    fprintf(stderr, "%s: the mesh has no extent (all its vertices coincide)\n", path);
    goto done;
  }
  float inv = (float)(1.0 / sqrt(diagonal));
  for (size_t v = 0; v < vertex_count; v++)
    for (int k = 0; k < 3; k++)
      positions[3 * v + k] = (positions[3 * v + k] - 0.5f * (report.bbox_min[k] + report.bbox_max[k])) * inv;
  if ((status = softshell_mesh_from_arrays(positions, vertex_count, triangles, triangle_count, &mesh)) !=
      SOFTSHELL_STATUS_OK) {
    code = fail("softshell_mesh_from_arrays", status);
    goto done;
  }

  SoftshellShellDef def = softshell_shell_def_default();
  def.stop_volume_ratio = (float)stop_ratio;
  def.threads = (uint32_t)threads;
  /* Off by default: a contracting shell at these settings does not reach itself, and the demo
     runs faster without the stage (-c 1 turns it on). */
  def.collisions = collisions != 0;
  if (pressure_given) def.pressure = (float)pressure;
  if ((status = softshell_shell_new(mesh, &def, &shell)) != SOFTSHELL_STATUS_OK) {
    code = fail("softshell_shell_new", status);
    goto done;
  }

  if (dir) {
    if (mkdir(dir, 0777) != 0 && errno != EEXIST) {
      fprintf(stderr, "cannot create directory %s: %s\n", dir, strerror(errno));
      goto done;
    }
    char csv_path[4096];
    snprintf(csv_path, sizeof csv_path, "%s/contract.csv", dir);
    csv = fopen(csv_path, "w");
    if (!csv) {
      fprintf(stderr, "cannot write %s: %s\n", csv_path, strerror(errno));
      goto done;
    }
    fprintf(csv, "step,volume_ratio,residual,elastic_energy,bending_energy,anisotropic_energy,step_ms\n");
    if ((status = write_frame(dir, 0, positions, vertex_count, triangles, triangle_count)) != SOFTSHELL_STATUS_OK) {
      code = fail("writing frame 0", status);
      goto done;
    }
  }

  printf("%s: %zu vertices, %zu triangles, scaled to a unit diagonal; pressure %g Pa, %u iteration(s), %u thread(s)\n",
         path, vertex_count, triangle_count, (double)def.pressure, def.iterations, (unsigned)threads);
  printf("%6s  %8s  %10s  %11s  %11s  %8s\n", "step", "V/V0", "residual", "elastic J", "bending J", "ms/step");
  SoftshellShellStats stats;
  memset(&stats, 0, sizeof stats);
  double total_ms = 0.0;
  for (unsigned long step = 1; step <= max_steps; step++) {
    status = softshell_shell_step(shell, &stats);
    if (status != SOFTSHELL_STATUS_OK) {
      code = fail("softshell_shell_step", status);
      goto done;
    }
    double ms = stats.step_seconds * 1e3;
    total_ms += ms;
    if (csv)
      fprintf(csv, "%lu,%.9g,%.6g,%.9g,%.9g,%.9g,%.4f\n", step, stats.volume_ratio, stats.residual,
              stats.elastic_energy, stats.bending_energy, stats.anisotropic_energy, ms);
    int last = stats.finished || step == max_steps;
    if (step % every == 0 || last) {
      printf("%6lu  %8.4f  %10.3e  %11.4e  %11.4e  %8.3f\n", step, stats.volume_ratio, stats.residual,
             stats.elastic_energy, stats.bending_energy, ms);
      if (dir) {
        status = softshell_shell_copy_positions(shell, positions, 3 * vertex_count, &len);
        if (status == SOFTSHELL_STATUS_OK)
          status = write_frame(dir, step, positions, vertex_count, triangles, triangle_count);
        if (status != SOFTSHELL_STATUS_OK) {
          code = fail("writing a frame", status);
          goto done;
        }
      }
    }
    if (stats.finished) break;
    if (stats.stalled) {
      printf("stalled: the volume ratio no longer changes\n");
      break;
    }
  }
  printf("%s after %llu steps (%.3f s simulated): V/V0 = %.4f, %.3f ms per step on average, %.1f MB held\n",
         stats.finished ? "finished" : "stopped", (unsigned long long)stats.step, stats.time, stats.volume_ratio,
         stats.step ? total_ms / (double)stats.step : 0.0, (double)softshell_shell_memory_bytes(shell) / 1e6);
  code = 0;

done:
  /* A table that could not be written is a failure, not a result. */
  if (csv && (ferror(csv) | fclose(csv)) != 0 && code == 0) {
    fprintf(stderr, "writing %s/contract.csv failed: %s\n", dir, strerror(errno));
    code = 1;
  }
  softshell_shell_free(shell);
  softshell_mesh_free(mesh);
  softshell_mesh_free(loaded);
  free(positions);
  free(triangles);
  return code;
}
