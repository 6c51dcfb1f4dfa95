/* errors: how a C program sees softshell's failures, checked under valgrind by `make check`.
 * Every call below is expected to fail in a specific way; the program exits 1 if one does not.
 * It shows the conventions: status codes, softshell_last_error(), outputs untouched on failure,
 * buffer size queries, NULL handling. */
#include <stdio.h>
#include <string.h>

#include "softshell.h"

static int failures = 0;

static void expect(const char *what, SoftshellStatus got, SoftshellStatus want) {
  if (got != want) {
    fprintf(stderr, "FAIL %s: got %s, want %s (%s)\n", what, softshell_status_name(got), softshell_status_name(want),
            softshell_last_error());
    failures++;
  } else {
    /* The message belongs to the last failing call: print it only for failures. */
    printf("%-28s %-17s %s\n", what, softshell_status_name(got), got == SOFTSHELL_STATUS_OK ? "" : softshell_last_error());
  }
}

int main(void) {
  static const float tetra_positions[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  static const uint32_t tetra_triangles[] = {0, 2, 1, 0, 1, 3, 1, 2, 3, 0, 3, 2};
  static const uint32_t bad_triangles[] = {0, 2, 1, 0, 1, 3, 1, 2, 9, 0, 3, 2};
  float nan_positions[12];
  memcpy(nan_positions, tetra_positions, sizeof tetra_positions);
  nan_positions[4] = 0.0f / 0.0f * 0.0f; /* a NaN without <math.h> */

  SoftshellMesh *mesh = NULL;
  expect("index out of range", softshell_mesh_from_arrays(tetra_positions, 4, bad_triangles, 4, &mesh),
         SOFTSHELL_STATUS_INVALID_MESH);
  if (mesh != NULL) failures++; /* outputs are written only on success */
  expect("NaN coordinate", softshell_mesh_from_arrays(nan_positions, 4, tetra_triangles, 4, &mesh),
         SOFTSHELL_STATUS_INVALID_MESH);
  expect("NULL positions", softshell_mesh_from_arrays(NULL, 4, tetra_triangles, 4, &mesh), SOFTSHELL_STATUS_NULL_ARGUMENT);
  expect("NULL out_mesh", softshell_mesh_from_arrays(tetra_positions, 4, tetra_triangles, 4, NULL),
         SOFTSHELL_STATUS_NULL_ARGUMENT);
  expect("missing file", softshell_mesh_load_obj("no/such/file.obj", &mesh), SOFTSHELL_STATUS_IO);
  expect("good mesh", softshell_mesh_from_arrays(tetra_positions, 4, tetra_triangles, 4, &mesh), SOFTSHELL_STATUS_OK);

  size_t needed = 0;
  float two[2] = {-1.0f, -1.0f};
  expect("size query (NULL buffer)", softshell_mesh_copy_positions(mesh, NULL, 0, &needed),
         SOFTSHELL_STATUS_BUFFER_TOO_SMALL);
  if (needed != 12) failures++;
  expect("short buffer", softshell_mesh_copy_positions(mesh, two, 2, &needed), SOFTSHELL_STATUS_BUFFER_TOO_SMALL);
  if (two[0] != -1.0f || two[1] != -1.0f) failures++; /* nothing written */
  expect("unknown curvature kind", softshell_mesh_copy_vertex_curvature(mesh, 42u, two, 2, &needed),
         SOFTSHELL_STATUS_INVALID_ARGUMENT);
  expect("NULL report", softshell_mesh_report(mesh, NULL), SOFTSHELL_STATUS_NULL_ARGUMENT);
  if (softshell_mesh_vertex_count(NULL) != 0) failures++;
  if (strcmp(softshell_status_name(12345u), "UNKNOWN") != 0) failures++;

  softshell_mesh_free(mesh);
  softshell_mesh_free(NULL); /* a no-op */
  if (failures) fprintf(stderr, "%d unexpected results\n", failures);
  return failures ? 1 : 0;
}
