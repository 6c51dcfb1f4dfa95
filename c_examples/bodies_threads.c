/* bodies_threads: the thread rules of a soft body, shown and checked. Three gas balls with two
 * worker threads each fall on the ground: the first is stepped from the main thread, the other two
 * from two threads of the program at the same time (different bodies may be stepped concurrently;
 * a body may move between threads). Every ball must end in the same state to the bit, whoever
 * stepped it: the library's results do not depend on the threads.
 *   bodies_threads [mesh.obj]     (default: data/sphere.obj)
 * Prints each ball's volume and heights; exit status 0 when they agree and rest on the ground, 1 on
 * any error or difference. */
#define _POSIX_C_SOURCE 200809L
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "softshell.h"

#define BALLS 3
#define STEPS 60 /* at 1/60 s: the balls reach the ground at about step 20 */

typedef struct Ball {
  SoftshellBody *body;
  SoftshellBodyStats stats;
  SoftshellStatus status;
} Ball;

/* Steps one ball STEPS times; the status of the first failed step, or OK. */
static void *step_ball(void *arg) {
  Ball *ball = arg;
  for (unsigned step = 0; step < STEPS; ++step) {
    ball->status = softshell_body_step(ball->body, &ball->stats);
    if (ball->status != SOFTSHELL_STATUS_OK) {
      fprintf(stderr, "step %u failed: %s: %s\n", step, softshell_status_name(ball->status),
              softshell_last_error());
      break;
    }
  }
  return NULL;
}

/* The height of the ball's centre (the mean of its vertices' y) and of its lowest vertex. */
static int heights_of(const SoftshellBody *body, double *y, double *lowest) {
  size_t n = 0;
  SoftshellStatus s = softshell_body_copy_positions(body, NULL, 0, &n);
  if (s != SOFTSHELL_STATUS_BUFFER_TOO_SMALL && s != SOFTSHELL_STATUS_OK) return 1;
  float *positions = malloc(n * sizeof *positions);
  if (!positions || softshell_body_copy_positions(body, positions, n, &n) != SOFTSHELL_STATUS_OK) {
    free(positions);
    return 1;
  }
  double sum = 0.0;
  *lowest = positions[1];
  for (size_t i = 1; i < n; i += 3) {
    sum += positions[i];
    if (positions[i] < *lowest) *lowest = positions[i];
  }
  *y = sum / (double)(n / 3);
  free(positions);
  return 0;
}

int main(int argc, char **argv) {
  const char *path = argc > 1 ? argv[1] : "data/sphere.obj";
  SoftshellMesh *mesh = NULL;
  SoftshellStatus status = softshell_mesh_load_obj(path, &mesh);
  if (status != SOFTSHELL_STATUS_OK) {
    fprintf(stderr, "softshell_mesh_load_obj failed: %s: %s\n", softshell_status_name(status), softshell_last_error());
    return 1;
  }
  SoftshellBodyDef def = softshell_body_def_default();
  def.threads = 2;
  def.total_mass = 1.0f;
  def.spring_stiffness = 400.0f;
  def.gas_amount = 300.0f;
  def.ground = true;
  def.ground_height = -1.5f;

  Ball balls[BALLS];
  memset(balls, 0, sizeof balls);
  int result = 0;
  for (int b = 0; b < BALLS && result == 0; ++b) {
    status = softshell_body_new(mesh, &def, &balls[b].body);
    if (status != SOFTSHELL_STATUS_OK) {
      fprintf(stderr, "softshell_body_new failed: %s: %s\n", softshell_status_name(status), softshell_last_error());
      result = 1;
    }
  }
  softshell_mesh_free(mesh);

  if (result == 0) {
    /* The first ball on this thread, then the other two at once on two threads of their own. */
    step_ball(&balls[0]);
    pthread_t threads[BALLS - 1];
    int started = 0;
    for (int b = 1; b < BALLS; ++b) {
      if (pthread_create(&threads[b - 1], NULL, step_ball, &balls[b]) != 0) {
        fprintf(stderr, "cannot start a thread\n");
        result = 1;
        break;
      }
      ++started;
    }
    for (int t = 0; t < started; ++t) pthread_join(threads[t], NULL);
  }

  double heights[BALLS] = {0.0}, lowest[BALLS] = {0.0};
  for (int b = 0; b < BALLS && result == 0; ++b) {
    if (balls[b].status != SOFTSHELL_STATUS_OK || heights_of(balls[b].body, &heights[b], &lowest[b]) != 0) {
      result = 1;
      break;
    }
    printf("ball %d (%s): volume %.6f m^3, centre at y = %.6f m, lowest vertex %.6f m, %llu CG iterations in the "
           "last step\n",
           b, b == 0 ? "main thread" : "own thread", balls[b].stats.volume, heights[b], lowest[b],
           (unsigned long long)balls[b].stats.solver_iterations);
  }
  for (int b = 1; b < BALLS && result == 0; ++b) {
    if (balls[b].stats.volume != balls[0].stats.volume || heights[b] != heights[0] || lowest[b] != lowest[0]) {
      fprintf(stderr, "ball %d differs from ball 0\n", b);
      result = 1;
    }
  }
  /* On the ground (its lowest vertex within 5 cm of it, not through it) after its fall. */
  if (result == 0 && (lowest[0] > (double)def.ground_height + 0.05 || lowest[0] < (double)def.ground_height - 0.01)) {
    fprintf(stderr, "the balls are not on the ground (lowest vertex at %.3f m)\n", lowest[0]);
    result = 1;
  }
  for (int b = 0; b < BALLS; ++b) softshell_body_free(balls[b].body);
  if (result == 0) printf("every ball ended in the same state\n");
  return result;
}
