#include "refine/switch_columns.hpp"

#include <cmath>
#include <vector>

#include "refine/fitted_sweep.hpp"
#include "refine/switch_perturbation.hpp"
#include "refine/switch_placement.hpp"
#include "refine/validate_fit.hpp"

namespace scp::refine {

namespace switch_model {

namespace {

// What a perturbation (D, y) entering a block (the state at the sample before its first) does over
// it: the state at its last sample, and the sum of its readings y over its samples.
struct BlockMap {
  PerturbationMap through = PerturbationMap::Identity();
  OutputRow readings = OutputRow::Zero();
  double count = 0.0;
};

// The row of `layout` a sample's t falls in, for t that never decrease.
class RowOf {
 public:
  explicit RowOf(const BlockLayout& layout) : layout_(layout) {}
  std::size_t operator()(double t) {
    const double at = std::floor((t - layout_.t0) / layout_.block_s);
    while (row_ + 1 < layout_.indices.size() &&
           static_cast<double>(layout_.indices[row_ + 1]) <= at)
      ++row_;
    return row_;
  }

 private:
  const BlockLayout& layout_;
  std::size_t row_ = 0;
};

// The fitted model's thermal block alone, sample by sample: what PerturbationSteps linearizes
// about, where the sensitivities of sweep_fitted_model are not needed.
class ThermalTrajectory {
 public:
  explicit ThermalTrajectory(const FitResult& fit)
      : theta_(fit.theta), tc_(fitted_tempcos(fit)), delay_(fit.input_delay_s) {
    state_.tbar = fit.initial_state[2];
  }
  // Advances over (prev.t, cur.t]; returns V² over it as the model sees it.
  double advance(const WindowSample& prev, const WindowSample& cur) {
    Piece pieces[2];
    const int n = pieces_between(prev, cur, pieces, delay_);
    for (int i = 0; i < n; ++i) advance_thermal_piece(theta_, pieces[i], state_, cache_, tc_);
    return mean_square_voltage(prev, cur, delay_);
  }
  const ModelState& state() const { return state_; }

 private:
  Vector6 theta_;
  Tempcos tc_;
  double delay_;
  ModelState state_;
  ThermalCache cache_;
};

// A perturbation below this fraction of its start has no weight left in any block mean.
constexpr double kNegligiblePerturbation = 1e-9;

Eigen::MatrixXd readings_at(std::span<const WindowSample> prepared, const FitResult& fit,
                            const BlockLayout& layout) {
  const std::vector<Switch> switches = switch_rows(prepared);
  const std::size_t rows = layout.indices.size(), n = switches.size();
  const double work = static_cast<double>(rows) * static_cast<double>(n) * static_cast<double>(n);
  if (n == 0 || n > kMostPlacedSwitches || rows == 0 || !(work <= kMostProjectedPhaseWork))
    return Eigen::MatrixXd(static_cast<Eigen::Index>(rows), 0);
  Eigen::MatrixXd out =
      Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(rows), static_cast<Eigen::Index>(n));
  std::vector<BlockMap> blocks(rows);
  std::vector<Perturbation> state(n, Perturbation::Zero());
  std::vector<std::size_t> first_row(n, 0);
  std::vector<std::size_t> open;  // the switches that started in the current block
  RowOf row_of(layout);
  PerturbationSteps steps(fit, Outputs::thermal);
  std::size_t next = 0, current = 0;
  PerturbationMap through = PerturbationMap::Identity();
  ThermalTrajectory model(fit);
  for (std::size_t k = 0; k < prepared.size(); ++k) {
    const std::size_t row = row_of(prepared[k].t);
    if (row != current) {
      blocks[current].through = through;
      through.setIdentity();
      open.clear();
      current = row;
    }
    if (k > 0) {
      const bool switch_row = next < n && switches[next].row == k;
      Perturbation start;
      const PerturbationMap a = steps.step(prepared, k, model.advance(prepared[k - 1], prepared[k]),
                                           switch_row ? &start : nullptr);
      through = a * through;
      for (std::size_t j : open) state[j] = a * state[j];
      if (switch_row) {
        state[next] = start;
        first_row[next] = row;
        open.push_back(next++);
      }
    }
    steps.passed(model.state());
    blocks[row].readings += through.row(kReading);
    blocks[row].count += 1.0;
    for (std::size_t j : open)
      out(static_cast<Eigen::Index>(row), static_cast<Eigen::Index>(j)) += state[j][kReading];
  }
  blocks[current].through = through;
  // Each switch's state leaving its own block, carried over the blocks after it.
  for (std::size_t j = 0; j < next; ++j) {
    Perturbation v = state[j];
    const double negligible = kNegligiblePerturbation * v.norm();
    for (std::size_t b = first_row[j] + 1; b < rows && v.norm() > negligible; ++b) {
      out(static_cast<Eigen::Index>(b), static_cast<Eigen::Index>(j)) = blocks[b].readings.dot(v);
      v = blocks[b].through * v;
    }
  }
  for (std::size_t b = 0; b < rows; ++b)
    if (blocks[b].count > 0.0) out.row(static_cast<Eigen::Index>(b)) /= blocks[b].count;
  return out;
}

}  // namespace

}  // namespace switch_model

Eigen::MatrixXd placed_switch_columns(std::span<const WindowSample> prepared, const FitResult& fit,
                                      const BlockLayout& layout) {
  return switch_model::readings_at(prepared, fit, layout);
}

}  // namespace scp::refine
