/* ccd_query: continuous collision queries in double precision.
 *   ccd_query
 * A vertex falls through a triangle, two edges cross, and a vertex passes beside a triangle;
 * prints whether each pair touches during the step and when. Exit status 0 when the answers are
 * the expected ones, 1 otherwise. */
#include <math.h>
#include <stdio.h>

#include "softshell.h"

static int fail(const char *what, SoftshellStatus status) {
  fprintf(stderr, "%s failed: %s: %s\n", what, softshell_status_name(status), softshell_last_error());
  return 1;
}

int main(void) {
  /* The triangle stays put; the vertex moves from 1 above it to 1 below: contact at t = 0.5. */
  const double a[3] = {0.0, 0.0, 0.0}, b[3] = {1.0, 0.0, 0.0}, c[3] = {0.0, 1.0, 0.0};
  const double p0[3] = {0.25, 0.25, 1.0}, p1[3] = {0.25, 0.25, -1.0};
  int32_t hit = 0;
  double toi = 0.0;
  SoftshellStatus status = softshell_ccd_vertex_triangle(p0, a, b, c, p1, a, b, c, 0.0, &hit, &toi);
  if (status != SOFTSHELL_STATUS_OK) return fail("softshell_ccd_vertex_triangle", status);
  printf("vertex through triangle: hit %d at t = %.9f\n", (int)hit, toi);
  int ok = hit == 1 && toi <= 0.5 && toi > 0.499;

  /* Edge cd sweeps down through edge ab (along x) at t = 0.5. */
  const double c0[3] = {0.5, -0.5, 1.0}, d0[3] = {0.5, 0.5, 1.0};
  const double c1[3] = {0.5, -0.5, -1.0}, d1[3] = {0.5, 0.5, -1.0};
  status = softshell_ccd_edge_edge(a, b, c0, d0, a, b, c1, d1, 0.0, &hit, &toi);
  if (status != SOFTSHELL_STATUS_OK) return fail("softshell_ccd_edge_edge", status);
  printf("crossing edges: hit %d at t = %.9f\n", (int)hit, toi);
  ok = ok && hit == 1 && toi <= 0.5 && toi > 0.499;

  /* The vertex passes beside the triangle, about 0.07 from its hypotenuse: a miss at thickness
     0.01, a hit at thickness 0.1. */
  const double q0[3] = {0.55, 0.55, 1.0}, q1[3] = {0.55, 0.55, -1.0};
  status = softshell_ccd_vertex_triangle(q0, a, b, c, q1, a, b, c, 0.01, &hit, &toi);
  if (status != SOFTSHELL_STATUS_OK) return fail("softshell_ccd_vertex_triangle", status);
  printf("vertex beside triangle, thickness 0.01: hit %d\n", (int)hit);
  ok = ok && hit == 0;
  status = softshell_ccd_vertex_triangle(q0, a, b, c, q1, a, b, c, 0.1, &hit, &toi);
  if (status != SOFTSHELL_STATUS_OK) return fail("softshell_ccd_vertex_triangle", status);
  printf("vertex beside triangle, thickness 0.1: hit %d at t = %.9f\n", (int)hit, toi);
  ok = ok && hit == 1;

  /* A NaN is refused and the outputs are left alone. */
  const double bad[3] = {0.0, NAN, 0.0};
  hit = -1;
  status = softshell_ccd_edge_edge(a, b, c0, d0, a, b, c1, bad, 0.0, &hit, &toi);
  printf("NaN input: %s (%s)\n", softshell_status_name(status), softshell_last_error());
  ok = ok && status == SOFTSHELL_STATUS_INVALID_ARGUMENT && hit == -1;

  puts(ok ? "all answers as expected" : "UNEXPECTED ANSWER");
  return ok ? 0 : 1;
}
