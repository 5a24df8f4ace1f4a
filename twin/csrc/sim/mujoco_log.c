/* MuJoCo's warnings for Python's logging, instead of MUJOCO_LOG.TXT in the working directory and the console.
 *
 * The handler (installed by twin.core.native with mju_setLogHandler) keeps the first LF_LOG_KEEP distinct messages with
 * how often each came, and counts the rest; Python drains them after each batch call (lf_log_drain) into the
 * "mujoco" logger. An unstable simulation warns at every step (the same few lines thousands of times), so keeping
 * a few and counting bounds both memory and the log. mujoco.batch
 * calls the handler from its worker threads: a mutex guards the store. Errors, and info messages of a topic
 * someone opted into, go on to the handler that was active before, as if this one were not there.
 */
#include <pthread.h>
#include <string.h>

#include <mujoco/mujoco.h>

#define LF_LOG_KEEP 8
#define LF_LOG_TEXT 512

static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static char kept[LF_LOG_KEEP][LF_LOG_TEXT];
static int32_t kept_level[LF_LOG_KEEP];
static int64_t kept_count[LF_LOG_KEEP]; /* how often each kept message came */
static int32_t nkept;
static int64_t received;   /* messages since the last drain, kept or not */
static mjfLogHandler next; /* the handler that was active before ours */

void lf_log_handler(const mjLogMessage *msg) {
  int32_t i;
  if (msg->level >= mjLOG_ERROR || msg->topic != mjTOPIC_NONE) { /* errors must not return; topics are opt-in */
    if (next) next(msg);
    return;
  }
  pthread_mutex_lock(&lock);
  for (i = 0; i < nkept; i++)
    if (kept_level[i] == msg->level && strncmp(kept[i], msg->subject, LF_LOG_TEXT - 1) == 0) break;
  if (i == nkept && nkept < LF_LOG_KEEP) {
    strncpy(kept[i], msg->subject, LF_LOG_TEXT - 1);
    kept[i][LF_LOG_TEXT - 1] = '\0';
    kept_level[i] = msg->level;
    kept_count[i] = 0;
    nkept++;
  }
  if (i < nkept) kept_count[i]++;
  received++;
  pthread_mutex_unlock(&lock);
}

/* Hand over the handler that was active before ours (mju_setLogHandler's return value). */
void lf_log_chain(mjfLogHandler previous) { next = previous; }

/* How many messages came since the last drain: a drain with nothing to hand over is skipped (Python drains after
 * every batch call, and a drain allocates its buffers). */
int64_t lf_log_pending(void) {
  int64_t n;
  pthread_mutex_lock(&lock);
  n = received;
  pthread_mutex_unlock(&lock);
  return n;
}

/* Copy up to n kept messages (text[n][text_size], level[n], count[n]) and forget them all; returns how many
 * messages came since the last drain, kept or not. Slots beyond those kept get count 0. */
int64_t lf_log_drain(char *text, int32_t *level, int64_t *count, int32_t n, int32_t text_size) {
  int64_t total;
  int32_t i;
  pthread_mutex_lock(&lock);
  total = received;
  for (i = 0; i < n; i++) {
    count[i] = i < nkept ? kept_count[i] : 0;
    if (i >= nkept) continue;
    strncpy(text + (int64_t)i * text_size, kept[i], (size_t)text_size - 1);
    text[(int64_t)i * text_size + text_size - 1] = '\0';
    level[i] = kept_level[i];
  }
  received = 0;
  nkept = 0;
  pthread_mutex_unlock(&lock);
  return total;
}
