// Plans with Ruckig 0.19.4 (target at rest) and samples the trajectory, for reference files.
// Reads lines: N q0[N] q1[N] v0[N] a0[N] vmax[N] amax[N] jmax[N] K
// and samples at K equally spaced times in [0, duration] plus one at duration + 0.1; writes one
// JSON line in microrobot's multi-joint format {"duration","times","q","qd","qdd","jerk"}, [time][joint].
#include <ruckig/ruckig.hpp>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>
using namespace ruckig;

template <size_t N>
static void solve(const std::vector<double>& x, int K) {
  InputParameter<N> in;
  for (size_t i = 0; i < N; ++i) {
    in.current_position[i] = x[0 * N + i];
    in.target_position[i] = x[1 * N + i];
    in.current_velocity[i] = x[2 * N + i];
    in.current_acceleration[i] = x[3 * N + i];
    in.max_velocity[i] = x[4 * N + i];
    in.max_acceleration[i] = x[5 * N + i];
    in.max_jerk[i] = x[6 * N + i];
    in.target_velocity[i] = 0;
    in.target_acceleration[i] = 0;
  }
  Ruckig<N> otg;
  Trajectory<N> tr;
  Result r = otg.calculate(in, tr);
  if (r != Result::Working) { std::printf("{\"error\":\"ruckig result %d\"}\n", int(r)); return; }
  const double T = tr.get_duration();
  std::vector<double> ts;
  for (int k = 0; k < K; ++k) ts.push_back(K > 1 ? T * k / (K - 1) : 0.0);
  ts.push_back(T + 0.1);
  std::vector<std::array<double, N>> P, V, A, J;
  for (double t : ts) {
    std::array<double, N> p, v, a, j;
    size_t sec;
    tr.at_time(t, p, v, a, j, sec);
    P.push_back(p); V.push_back(v); A.push_back(a); J.push_back(j);
  }
  auto dump = [&](const char* name, const std::vector<std::array<double, N>>& M) {
    std::printf(",\"%s\":[", name);
    for (size_t k = 0; k < M.size(); ++k) {
      std::printf("%s[", k ? "," : "");
      for (size_t i = 0; i < N; ++i) std::printf("%s%.17g", i ? "," : "", M[k][i]);
      std::printf("]");
    }
    std::printf("]");
  };
  std::printf("{\"duration\":%.17g,\"times\":[", T);
  for (size_t k = 0; k < ts.size(); ++k) std::printf("%s%.17g", k ? "," : "", ts[k]);
  std::printf("]");
  dump("q", P); dump("qd", V); dump("qdd", A); dump("jerk", J);
  std::printf("}\n");
}

int main() {
  std::string line;
  while (std::getline(std::cin, line)) {
    if (line.empty()) continue;
    std::istringstream ss(line);
    size_t n; ss >> n;
    std::vector<double> x(7 * n);
    for (auto& v : x) { std::string tok; ss >> tok; v = std::strtod(tok.c_str(), nullptr); }
    int K; ss >> K;
    switch (n) {
      case 1: solve<1>(x, K); break;
      case 2: solve<2>(x, K); break;
      case 6: solve<6>(x, K); break;
      default: std::printf("{\"error\":\"dof\"}\n");
    }
    std::fflush(stdout);
  }
}
