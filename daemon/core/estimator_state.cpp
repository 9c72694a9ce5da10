#include "daemon/core/estimator_state.hpp"

#include <chrono>

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

state::Checkpoint to_checkpoint(const EstimatorStateView& v, const std::string& driver,
                                const std::string& actuator, const std::string& endpoint) {
  state::Checkpoint c;
  c.theta_hat = v.theta_hat;
  c.info_mech = v.info_mech;
  c.info_thermal = v.info_thermal;
  c.eps2_mean = v.eps2_mean;
  c.t = v.t;
  c.driver = driver;
  c.actuator = actuator;
  c.endpoint = endpoint;
  c.wall_time_unix = std::chrono::duration_cast<std::chrono::seconds>(
                         std::chrono::system_clock::now().time_since_epoch())
                         .count();
  return c;
}

EstimatorStateView to_view(const state::Checkpoint& c) noexcept {
  EstimatorStateView v;
  v.theta_hat = c.theta_hat;
  v.info_mech = c.info_mech;
  v.info_thermal = c.info_thermal;
  v.eps2_mean = c.eps2_mean;
  v.t = c.t;
  v.valid = true;
  return v;
}

}  // namespace scp::daemon
