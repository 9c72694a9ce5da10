#include "daemon/core/estimator_state.hpp"

namespace scp::daemon {

EstimatorStateView to_view(const estimator::State& s) noexcept {
  EstimatorStateView v;
  Eigen::Map<Eigen::Matrix<double, 6, 1>>(v.theta_hat.data()) = s.theta_hat;
  Eigen::Map<Eigen::Matrix<double, 4, 4, Eigen::RowMajor>>(v.info_mech.data()) = s.info_mech;
  Eigen::Map<Eigen::Matrix<double, 2, 2, Eigen::RowMajor>>(v.info_thermal.data()) = s.info_thermal;
  v.eps2_mean = {s.eps2_mean[0], s.eps2_mean[1]};
  v.t = s.t;
  v.valid = true;
  return v;
}

estimator::State to_state(const EstimatorStateView& v) noexcept {
  estimator::State s;
  s.theta_hat = Eigen::Map<const Eigen::Matrix<double, 6, 1>>(v.theta_hat.data());
  s.info_mech = Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>>(v.info_mech.data());
  s.info_thermal =
      Eigen::Map<const Eigen::Matrix<double, 2, 2, Eigen::RowMajor>>(v.info_thermal.data());
  s.eps2_mean = {v.eps2_mean[0], v.eps2_mean[1]};
  s.t = v.t;
  return s;
}

}  // namespace scp::daemon
