#include "refine/delay_batch_means.hpp"

#include <cmath>
#include <vector>

#include "refine/delay_differences.hpp"

namespace scp::refine {

BatchMeansCheck check_delay_against_batch_means(const PassResult& below, const PassResult& at,
                                                const PassResult& above, double h, FreeMask free,
                                                std::size_t delay_slot) {
  const std::size_t k = at.batch_scores.size();
  const auto matches = [k](const PassResult& r) {
    return r.finite && r.batch_scores.size() == k && r.batch_information.size() == k &&
           r.batch_costs.size() == k;
  };
  if (k < 2 || !(h > 0.0) || !std::isfinite(h) || delay_slot >= free.size() || free[delay_slot] ||
      !matches(below) || !matches(at) || !matches(above)) {
    return {};
  }
  std::vector<ParamVector> scores(k);
  std::vector<ParamMatrix> information(k);
  ParamMatrix normal = ParamMatrix::Zero();
  const auto slot = static_cast<Eigen::Index>(delay_slot);
  for (std::size_t b = 0; b < k; ++b) {
    const DelayDifferences d =
        delay_differences(below.batch_costs[b], at.batch_costs[b], above.batch_costs[b],
                          below.batch_scores[b], above.batch_scores[b], h);
    ParamVector g = at.batch_scores[b];
    ParamMatrix hb = at.batch_information[b];
    g[slot] = d.score;
    hb(slot, slot) = d.information;
    for (Eigen::Index j = 0; j < kParams; ++j) {
      if (j == slot) continue;
      const double c = free[static_cast<std::size_t>(j)] ? d.cross[j] : 0.0;
      hb(slot, j) = c;
      hb(j, slot) = c;
    }
    scores[b] = g;
    information[b] = hb;
    normal += hb;
  }
  if (!normal.allFinite()) return {};
  free[delay_slot] = true;
  ParamMatrix covariance = ParamMatrix::Zero();
  if (!inverse_on_free(normal, free, covariance)) return {};
  return check_against_batch_means(covariance, normal, scores, information, free);
}

}  // namespace scp::refine
