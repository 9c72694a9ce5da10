#pragma once
// Golden-section search for the minimum of a cost on an interval: the fit's 1-D searches (the
// voltage's delay, the common scale of θ1..θ4), where each cost is a pass over the window and a
// derivative would cost as much again.

#include <cmath>

namespace scp::refine {

struct GoldenResult {
  double x = 0.0;
  double cost = 0.0;
};

// The minimum of `cost` on [a, b], until the bracket is narrower than `tolerance` (at most
// max_steps steps, fewer when `stop()` says so); `steps` counts them.
template <class Cost, class Stop>
GoldenResult golden_section(double a, double b, double tolerance, int max_steps, Cost&& cost,
                            Stop&& stop, int& steps) {
  const double g = 0.5 * (std::sqrt(5.0) - 1.0);
  double x1 = b - g * (b - a), x2 = a + g * (b - a);
  double f1 = cost(x1), f2 = cost(x2);
  for (int i = 0; i < max_steps && b - a > tolerance && !stop(); ++i) {
    ++steps;
    if (f1 < f2) {
      b = x2;
      x2 = x1;
      f2 = f1;
      x1 = b - g * (b - a);
      f1 = cost(x1);
    } else {
      a = x1;
      x1 = x2;
      f1 = f2;
      x2 = a + g * (b - a);
      f2 = cost(x2);
    }
  }
  return f1 < f2 ? GoldenResult{x1, f1} : GoldenResult{x2, f2};
}

}  // namespace scp::refine
