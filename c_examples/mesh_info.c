/* mesh_info: load an OBJ file and print what softshell sees in it.
 *   mesh_info [file.obj]        (default data/kitten.obj)
 * Exit status 0 on success, 1 on any error (the library's message is printed). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "softshell.h"

static int fail(const char *what, SoftshellStatus status) {
  fprintf(stderr, "%s failed: %s: %s\n", what, softshell_status_name(status), softshell_last_error());
  return 1;
}

int main(int argc, char **argv) {
  const char *path = argc > 1 ? argv[1] : "data/kitten.obj";

  /* A library built from other sources than this header would misbehave: refuse it. */
  if (softshell_abi_version() != SOFTSHELL_ABI_VERSION ||
      strcmp(softshell_version_string(), SOFTSHELL_VERSION_STRING) != 0) {
    fprintf(stderr, "header %s does not match library %s\n", SOFTSHELL_VERSION_STRING, softshell_version_string());
    return 1;
  }

  SoftshellMesh *mesh = NULL;
  SoftshellStatus status = softshell_mesh_load_obj(path, &mesh);
  if (status != SOFTSHELL_STATUS_OK) return fail("softshell_mesh_load_obj", status);

  SoftshellMeshReport r;
  status = softshell_mesh_report(mesh, &r);
  if (status != SOFTSHELL_STATUS_OK) {
    softshell_mesh_free(mesh);
    return fail("softshell_mesh_report", status);
  }

  printf("file                      %s (softshell %s)\n", path, softshell_version_string());
  printf("vertices                  %zu (%zu unreferenced)\n", r.vertex_count, r.unreferenced_vertices);
  printf("edges                     %zu\n", r.edge_count);
  printf("triangles                 %zu\n", r.triangle_count);
  printf("boundary edges            %zu\n", r.boundary_edges);
  printf("non-manifold edges        %zu\n", r.non_manifold_edges);
  printf("non-manifold vertices     %zu\n", r.non_manifold_vertices);
  printf("degenerate triangles      %zu\n", r.degenerate_triangles);
  printf("components                %zu\n", r.components);
  printf("genus                     %d\n", (int)r.genus);
  printf("closed                    %s\n", r.is_closed ? "yes" : "no");
  printf("consistently oriented     %s\n", r.is_consistently_oriented ? "yes" : "no");
  printf("area                      %.9g\n", r.area);
  printf("volume                    %.9g\n", r.volume);
  printf("smallest angle (degrees)  %.4g\n", r.min_angle_degrees);
  printf("bounding box              (%g, %g, %g) .. (%g, %g, %g)\n", (double)r.bbox_min[0], (double)r.bbox_min[1],
         (double)r.bbox_min[2], (double)r.bbox_max[0], (double)r.bbox_max[1], (double)r.bbox_max[2]);

  /* Curvature: ask for the size first, then copy. */
  size_t needed = 0;
  status = softshell_mesh_copy_vertex_curvature(mesh, SOFTSHELL_CURVATURE_MEAN, NULL, 0, &needed);
  if (status != SOFTSHELL_STATUS_BUFFER_TOO_SMALL) {
    softshell_mesh_free(mesh);
    return fail("softshell_mesh_copy_vertex_curvature (size query)", status);
  }
  float *mean = (float *)malloc(needed * sizeof *mean);
  float *gauss = (float *)malloc(needed * sizeof *gauss);
  size_t written = 0;
  if (!mean || !gauss) {
    free(mean);
    free(gauss);
    softshell_mesh_free(mesh);
    fprintf(stderr, "out of memory\n");
    return 1;
  }
  status = softshell_mesh_copy_vertex_curvature(mesh, SOFTSHELL_CURVATURE_MEAN, mean, needed, &written);
  if (status == SOFTSHELL_STATUS_OK)
    status = softshell_mesh_copy_vertex_curvature(mesh, SOFTSHELL_CURVATURE_GAUSSIAN, gauss, needed, &written);
  if (status == SOFTSHELL_STATUS_OK) {
    /* Gauss-Bonnet would need the vertex areas; print plain averages and extremes instead. */
    double mean_sum = 0.0, gauss_sum = 0.0, mean_min = mean[0], mean_max = mean[0];
    for (size_t i = 0; i < written; i++) {
      mean_sum += mean[i];
      gauss_sum += gauss[i];
      if (mean[i] < mean_min) mean_min = mean[i];
      if (mean[i] > mean_max) mean_max = mean[i];
    }
    printf("mean curvature            average %.4g, range %.4g .. %.4g\n", mean_sum / (double)written, mean_min, mean_max);
    printf("Gaussian curvature        average %.4g\n", gauss_sum / (double)written);
  }
  free(mean);
  free(gauss);
  softshell_mesh_free(mesh);
  if (status != SOFTSHELL_STATUS_OK) return fail("softshell_mesh_copy_vertex_curvature", status);
  return 0;
}
