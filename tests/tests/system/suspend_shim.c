/* A host suspend as one process sees it, for tests/tests/system/safety.rs: preloaded
 * (LD_PRELOAD), it takes the nanoseconds written in the file $SCOUT_SUSPEND_SHIM_FILE off
 * CLOCK_MONOTONIC (and its raw and coarse forms), which a real suspend does not count, and
 * leaves CLOCK_BOOTTIME and CLOCK_REALTIME alone, which do. The test stops the process
 * (SIGSTOP) for a while, writes that while into the file and lets it go on (SIGCONT): its
 * monotonic clock then shows no gap, as after a suspend. With $SCOUT_SUSPEND_SHIM_ALL set,
 * CLOCK_BOOTTIME is shifted too (a clock that does not count the suspend either). */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <fcntl.h>
#include <stdlib.h>
#include <time.h>
#include <unistd.h>

static long long offset_ns(void) {
    const char *path = getenv("SCOUT_SUSPEND_SHIM_FILE");
    if (path == NULL) return 0;
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0) return 0;
    char text[32] = {0};
    ssize_t n = read(fd, text, sizeof text - 1);
    close(fd);
    return n > 0 ? atoll(text) : 0;
}

int clock_gettime(clockid_t clock, struct timespec *time) {
    static int (*real)(clockid_t, struct timespec *);
    if (real == NULL) real = (int (*)(clockid_t, struct timespec *))dlsym(RTLD_NEXT, "clock_gettime");
    int result = real(clock, time);
    int shifted = clock == CLOCK_MONOTONIC || clock == CLOCK_MONOTONIC_RAW
        || clock == CLOCK_MONOTONIC_COARSE
        || (clock == CLOCK_BOOTTIME && getenv("SCOUT_SUSPEND_SHIM_ALL") != NULL);
    if (result == 0 && shifted) {
        long long ns = (long long)time->tv_sec * 1000000000LL + time->tv_nsec - offset_ns();
        time->tv_sec = ns / 1000000000LL;
        time->tv_nsec = ns % 1000000000LL;
    }
    return result;
}
