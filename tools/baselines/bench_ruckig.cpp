// Ruckig 0.19.4 (community, no cloud client) benchmark, Ruckig<6> static DOF, offline calculate().
// Inputs: data/table4.txt (from tests/reference/trajectory_reference.json),
//         data/model.txt (joint ranges), data/online_sync.txt (validation of state-to-state durations).
//
// Usage: bench_ruckig [seconds_per_benchmark=2.0] [n_state_problems=30000]
#include <ruckig/ruckig.hpp>

#include <time.h>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <random>
#include <string>
#include <vector>

using namespace ruckig;
using Vec6 = std::array<double, 6>;

#include "bench_timing.hpp"

// Per-problem thread CPU time of `calculate` (mean of REP back-to-back solves inside one
// clock pair), Ruckig's errors, and the mean trajectory duration.
template <class Problems>
static Distribution time_problems(Ruckig<6>& otg, Trajectory<6>& traj, const Problems& ps, long& errors,
                                  double& mean_duration) {
  constexpr int REP = 8;
  std::vector<double> per(ps.size());
  errors = 0;
  double dsum = 0;
  for (size_t k = 0; k < ps.size(); ++k) {
    Result res = Result::Working;
    double a = thread_ns();
    for (int r = 0; r < REP; ++r) { res = otg.calculate(ps[k], traj); BARRIER(); }
    double b = thread_ns();
    per[k] = (b - a) / REP;
    if (res != Result::Working) ++errors;
    dsum += traj.get_duration();
  }
  mean_duration = dsum / double(ps.size());
  return Distribution(std::move(per));
}

int main(int argc, char** argv) {
  const double seconds = argc > 1 ? std::atof(argv[1]) : 2.0;
  const int nprob = argc > 2 ? std::atoi(argv[2]) : 30000;
  const std::string dir = "data/";  // written by gen_inputs.py; run.sh runs from its work dir

  Vec6 p0t4, p1t4, vmax, amax, jmax, qmin, qmax;
  double ref_duration;
  {
    std::ifstream f(dir + "table4.txt");
    for (int i = 0; i < 6; ++i) f >> p0t4[i] >> p1t4[i] >> vmax[i] >> amax[i] >> jmax[i];
    f >> ref_duration;
    std::ifstream fm(dir + "model.txt");
    double g[3], x;
    int nj;
    fm >> g[0] >> g[1] >> g[2] >> nj;
    for (int i = 0; i < 6; ++i) {
      fm >> x >> x >> x >> x >> qmin[i] >> qmax[i];
      for (int k = 0; k < 17; ++k) fm >> x;  // vmax amax jmax m com(3) I(9) rotor
    }
    if (!f || !fm) { std::fprintf(stderr, "bad input files\n"); return 1; }
  }

  Ruckig<6> otg;  // no control cycle: offline calculate(input, trajectory)
  Trajectory<6> traj;

  // ---------------- 1. Table 4 rest-to-rest ----------------
  InputParameter<6> t4;
  t4.current_position = p0t4;
  t4.current_velocity = {0, 0, 0, 0, 0, 0};
  t4.current_acceleration = {0, 0, 0, 0, 0, 0};
  t4.target_position = p1t4;
  t4.target_velocity = {0, 0, 0, 0, 0, 0};
  t4.target_acceleration = {0, 0, 0, 0, 0, 0};
  t4.max_velocity = vmax;
  t4.max_acceleration = amax;
  t4.max_jerk = jmax;
  Result r = otg.calculate(t4, traj);
  std::printf("Ruckig 0.19.4: Table 4 result %d duration %.15f (reference %.15f, diff %.2e)\n", int(r),
              traj.get_duration(), ref_duration, traj.get_duration() - ref_duration);
  if (r != Result::Working || std::abs(traj.get_duration() - ref_duration) > 1e-9) {
    std::printf("VALIDATION FAILED\n");
    return 2;
  }
  // validation: online synchronized reference durations
  {
    std::ifstream f(dir + "online_sync.txt");
    int n;
    f >> n;
    double maxd = 0;
    for (int c = 0; c < n; ++c) {
      InputParameter<6> in;
      for (auto* v : {&in.current_position, &in.current_velocity, &in.current_acceleration, &in.target_position,
                      &in.max_velocity, &in.max_acceleration, &in.max_jerk})
        for (double& x : *v) f >> x;
      double d;
      f >> d;
      in.target_velocity = {0, 0, 0, 0, 0, 0};
      in.target_acceleration = {0, 0, 0, 0, 0, 0};
      Trajectory<6> tr;
      Result rr = otg.calculate(in, tr);
      if (rr != Result::Working) { std::printf("online case %d result %d\n", c, int(rr)); return 2; }
      maxd = std::max(maxd, std::abs(tr.get_duration() - d));
    }
    std::printf("online_trajectory_reference synchronized: %d cases, max |duration - ref| = %.2e s\n", n, maxd);
    if (!(maxd < 1e-9)) { std::printf("VALIDATION FAILED\n"); return 2; }
  }
  volatile double sink = 0;

  run_bench("(empty loop: timer overhead)", [&](size_t) {}, seconds / 4);
  run_bench("1. calculate Table4 rest-to-rest", [&](size_t) { otg.calculate(t4, traj); }, seconds);
  sink = sink + traj.get_duration();

  // ---------------- 2. random rest-to-rest ----------------
  std::mt19937_64 rng(4242);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  auto U = [&](double lo, double hi) { return lo + (hi - lo) * u01(rng); };
  constexpr int NR = 1024;
  std::vector<InputParameter<6>> rr(NR);
  for (auto& in : rr) {
    for (int i = 0; i < 6; ++i) {
      in.current_position[i] = U(-2, 2);
      in.target_position[i] = U(-2, 2);
      in.current_velocity[i] = in.current_acceleration[i] = in.target_velocity[i] = in.target_acceleration[i] = 0;
      in.max_velocity[i] = vmax[i] * U(0.5, 1.5);
      in.max_acceleration[i] = amax[i] * U(0.5, 1.5);
      in.max_jerk[i] = jmax[i] * U(0.5, 1.5);
    }
    if (otg.calculate(in, traj) != Result::Working) { std::printf("random rest-to-rest failed\n"); return 2; }
  }
  run_bench("2. calculate random rest-to-rest", [&](size_t k) { otg.calculate(rr[k & (NR - 1)], traj); }, seconds);
  sink = sink + traj.get_duration();

  // ---------------- 4. at_time on the Table 4 trajectory ----------------
  otg.calculate(t4, traj);
  const double dur = traj.get_duration();
  constexpr int NT = 1000;
  std::vector<double> ts(NT);
  for (int i = 0; i < NT; ++i) ts[i] = dur * i / (NT - 1);
  Vec6 np, nv, na, nj;
  size_t sec = 0;
  run_bench("4a. at_time(t, p, v, a)", [&](size_t k) { traj.at_time(ts[k % NT], np, nv, na); }, seconds);
  sink = sink + np[0] + nv[1] + na[2];
  run_bench("4b. at_time(t, p, v, a, j, section)", [&](size_t k) { traj.at_time(ts[k % NT], np, nv, na, nj, sec); },
            seconds);
  sink = sink + np[0] + nj[3] + double(sec);

  // ---------------- 3. random state-to-state, target at rest ----------------
  std::vector<InputParameter<6>> sp(nprob);
  long rejected = 0;
  for (auto& in : sp) {
    for (int i = 0; i < 6; ++i) {
      double v0, a0;
      do {  // mirror online_trajectory_reference: exclude states that must overshoot vmax (brake pre-phase)
        v0 = U(-vmax[i], vmax[i]);
        a0 = U(-amax[i], amax[i]);
        double vs = v0 + a0 * std::abs(a0) / (2 * jmax[i]);
        if (vs > -vmax[i] && vs < vmax[i]) break;
        ++rejected;
      } while (true);
      in.current_position[i] = U(qmin[i], qmax[i]);
      in.current_velocity[i] = v0;
      in.current_acceleration[i] = a0;
      in.target_position[i] = U(qmin[i], qmax[i]);
      in.target_velocity[i] = in.target_acceleration[i] = 0;
      in.max_velocity[i] = vmax[i];
      in.max_acceleration[i] = amax[i];
      in.max_jerk[i] = jmax[i];
    }
  }
  // warm-up
  for (int k = 0; k < std::min(nprob, 2000); ++k) otg.calculate(sp[k], traj);
  // timer overhead of one clock pair
  double ovh = 1e300;
  for (int k = 0; k < 10000; ++k) {
    double a = thread_ns();
    BARRIER();
    double b = thread_ns();
    ovh = std::min(ovh, b - a);
  }
  long errors = 0;
  double mean_duration = 0;
  const Distribution d3 = time_problems(otg, traj, sp, errors, mean_duration);
  std::printf("3. state-to-state (target at rest), %d problems x 8 repeats (per-problem mean of 8, one clock pair"
              " per problem; clock-pair overhead %.0f ns /8 = %.1f ns, NOT subtracted):\n"
              "   mean %.1f ns  p50 %.1f  p90 %.1f  p99 %.1f  p99.9 %.1f  max %.1f  min %.1f ns; errors %ld; rejected"
              " draws %ld; mean duration %.3f s\n",
              nprob, ovh, ovh / 8, d3.mean, d3.pct(0.5), d3.pct(0.9), d3.pct(0.99), d3.pct(0.999), d3.sorted.back(),
              d3.sorted.front(), errors, rejected, mean_duration);

  // ---------------- 3b. the SAME problems as microrobot's cpu_time / criterion (benches/common/mod.rs) ----------------
  {
    std::uint64_t st = 30303;
    auto lcg = [&]() { st = st * 6364136223846793005ULL + 1442695040888963407ULL; return double(st >> 11) / double(1ULL << 53); };
    const double big[6] = {135, 70, 70, 135, 70, 135};
    const double d2r = M_PI / 180.0;
    std::vector<InputParameter<6>> mp(nprob);
    for (auto& in : mp) {
      for (int i = 0; i < 6; ++i) {
        double am = std::round(big[i] * 80.0 / 135.0);
        double v = big[i] * d2r, a = am * d2r, j = 2.0 * am * d2r;
        double a0 = (2.0 * lcg() - 1.0) * a;
        double s = a0 * std::abs(a0) / (2.0 * j);
        double lo = std::max(-v, -v - s), hi = std::min(v, v - s);
        in.current_position[i] = (2.0 * lcg() - 1.0) * 2.5;
        in.current_velocity[i] = lo + lcg() * (hi - lo);
        in.current_acceleration[i] = a0;
        in.target_position[i] = (2.0 * lcg() - 1.0) * 2.5;
        in.target_velocity[i] = in.target_acceleration[i] = 0;
        in.max_velocity[i] = v; in.max_acceleration[i] = a; in.max_jerk[i] = j;
      }
    }
    for (int k = 0; k < std::min(nprob, 2000); ++k) otg.calculate(mp[k], traj);
    const Distribution d = time_problems(otg, traj, mp, errors, mean_duration);
    std::printf("3b. state-to-state, microrobot's problem set (LCG 30303, q in +-2.5 rad, Table 4 limits), %d problems"
                " x 8:\n   mean %.1f ns  p50 %.1f  p90 %.1f  p99 %.1f  p99.9 %.1f  max %.1f ns; errors %ld; mean"
                " duration %.3f s\n",
                nprob, d.mean, d.pct(0.5), d.pct(0.9), d.pct(0.99), d.pct(0.999), d.sorted.back(), errors,
                mean_duration);
  }
  std::printf("(sink %g)\n", double(sink));
  return 0;
}
