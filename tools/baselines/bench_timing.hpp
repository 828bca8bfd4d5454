// Timing helpers shared by bench_pin.cpp and bench_ruckig.cpp: thread CPU time around
// batches of 256 calls, after 0.3 s of warm-up; the mean and the best batch per call.
#pragma once
#include <time.h>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

static inline double thread_ns() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) * 1e9 + double(ts.tv_nsec);
}
#define BARRIER() asm volatile("" ::: "memory")

struct Stat { double mean_ns, best_ns; long calls; };

// Times f(k) for `seconds` of thread CPU time and prints one line.
template <class F>
static Stat run_bench(const char* name, F&& f, double seconds) {
  constexpr int B = 256;
  size_t k = 0;
  double t0 = thread_ns();
  while (thread_ns() - t0 < 0.3e9)
    for (int i = 0; i < B; ++i) { f(k++); BARRIER(); }
  double total = 0, best = 1e300;
  long nb = 0;
  while (total < seconds * 1e9) {
    double a = thread_ns();
    for (int i = 0; i < B; ++i) { f(k++); BARRIER(); }
    double b = thread_ns();
    total += b - a;
    best = std::min(best, b - a);
    ++nb;
  }
  Stat s{total / double(nb * B), best / B, nb * B};
  std::printf("%-40s mean %9.2f ns   best-batch %9.2f ns   (%ld calls)\n", name, s.mean_ns, s.best_ns, s.calls);
  std::fflush(stdout);
  return s;
}

// Mean and nearest-rank percentiles of per-problem times.
struct Distribution {
  std::vector<double> sorted;
  double mean = 0;
  explicit Distribution(std::vector<double> xs) : sorted(std::move(xs)) {
    std::sort(sorted.begin(), sorted.end());
    for (double x : sorted) mean += x;
    mean /= double(sorted.size());
  }
  double pct(double p) const {
    return sorted[std::min<size_t>(sorted.size() - 1, size_t(std::ceil(p * double(sorted.size()))) - 1)];
  }
};
