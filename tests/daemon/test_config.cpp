// Configuration: the shipped files load, and every mistake names the key, the line and the range.

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>
#include <string>
#include <tuple>

#include "daemon/config/binder.hpp"
#include "daemon/config/daemon_config.hpp"
#include "daemon/config/reference_man.hpp"
#include "daemon/config/startup_checks.hpp"

namespace scp::config {
namespace {

std::string error_of(const std::string& yaml) {
  try {
    load_config_text(yaml, "test.yaml");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(Config, ShippedFilesLoad) {
  for (const char* name : {"paper.yaml", "sim.yaml"}) {
    const auto cfg = load_config_file(std::string(SCP_SOURCE_DIR) + "/config/" + name);
    EXPECT_EQ(cfg.driver.type, DriverType::sim) << name;
  }
  const auto paper = load_config_file(std::string(SCP_SOURCE_DIR) + "/config/paper.yaml");
  EXPECT_EQ(paper.estimator.beta, 3.0);
  EXPECT_EQ(paper.estimator.forgetting, 0.8);
  EXPECT_EQ(paper.estimator.p0, 100.0);
  EXPECT_EQ(paper.excitation.settings.sines.size(), 4U);
}

TEST(Config, EmptyDocumentGivesDefaults) {
  const auto cfg = load_config_text("", "empty.yaml");
  EXPECT_EQ(cfg.loop.period_s, 0.001);
  EXPECT_EQ(cfg.driver.type, DriverType::sim);
}

// The loop's tests start from the structs' defaults completed by derive_settings, not from the
// loader (they link neither YAML nor a driver): the defaults are written in the structs and in the
// declarations, and must agree on everything the loop and the simulated actuator read.
TEST(Config, StructDefaultsAreTheDeclaredOnes) {
  const DaemonConfig loaded = load_config_text("{}", "empty.yaml");
  DaemonConfig built;
  derive_settings(built);
#define SCP_SAME(field) EXPECT_EQ(loaded.field, built.field) << #field
  SCP_SAME(loop.period_s);
  SCP_SAME(actuator.name);
  SCP_SAME(actuator.ambient_c);
  SCP_SAME(actuator.mass_kg);
  SCP_SAME(actuator.resistance_ohm);
  SCP_SAME(driver.type);
  SCP_SAME(driver.velocity.method);
  SCP_SAME(driver.velocity.bandwidth_hz);
  SCP_SAME(driver.velocity.damping);
  const auto& plant = built.driver.sim.plant;
  for (const auto& [name, value, declared] :
       {std::tuple{"m", plant.m, loaded.driver.sim.plant.m},
        std::tuple{"R", plant.R, loaded.driver.sim.plant.R},
        std::tuple{"Cth", plant.Cth, loaded.driver.sim.plant.Cth},
        std::tuple{"lambda", plant.lambda, loaded.driver.sim.plant.lambda},
        std::tuple{"b", plant.b, loaded.driver.sim.plant.b},
        std::tuple{"k", plant.k, loaded.driver.sim.plant.k},
        std::tuple{"alpha1", plant.alpha1, loaded.driver.sim.plant.alpha1},
        std::tuple{"alpha2", plant.alpha2, loaded.driver.sim.plant.alpha2}}) {
    EXPECT_EQ(declared, value) << "driver.sim.plant." << name;
  }
  SCP_SAME(driver.sim.ambient_c);
  SCP_SAME(driver.sim.substeps);
  SCP_SAME(driver.sim.noise_x);
  SCP_SAME(driver.sim.noise_xdot);
  SCP_SAME(driver.sim.noise_temperature);
  SCP_SAME(driver.sim.noise_voltage);
  SCP_SAME(driver.sim.seed);
  SCP_SAME(driver.sim.measure_xdot);
  SCP_SAME(driver.sim.fault);
  SCP_SAME(estimator.beta);
  SCP_SAME(estimator.forgetting);
  SCP_SAME(estimator.forgetting_mechanical);
  SCP_SAME(estimator.p0);
  SCP_SAME(estimator.p_max);
  SCP_SAME(estimator.theta0);
  SCP_SAME(estimator.scale);
  SCP_SAME(estimator.known);
  SCP_SAME(estimator.voltage_hold);
  SCP_SAME(estimator.max_gap_periods);
  SCP_SAME(estimator.nominal_period);
  SCP_SAME(estimator.x_abs_max);
  SCP_SAME(estimator.xdot_abs_max);
  SCP_SAME(estimator.tbar_min);
  SCP_SAME(estimator.tbar_max);
  SCP_SAME(estimator.voltage_max);
  SCP_SAME(estimator.converged_rel_sigma);
  SCP_SAME(excitation.enabled);
  SCP_SAME(excitation.profile);
  SCP_SAME(excitation.settings.v_max);
  SCP_SAME(excitation.settings.offset);
  SCP_SAME(excitation.settings.sines.size());
  SCP_SAME(excitation.settings.steps.size());
  SCP_SAME(excitation.settings.prbs.amplitude);
  SCP_SAME(safety.voltage_max_v);
  SCP_SAME(safety.temperature_max_c);
  SCP_SAME(safety.temperature_min_c);
  SCP_SAME(safety.position_abs_max_m);
  SCP_SAME(safety.stale_timeout_s);
  SCP_SAME(safety.recover_after_s);
  SCP_SAME(safety.stuck_timeout_s);
  SCP_SAME(refine.enabled);
  SCP_SAME(refine.window_s);
  SCP_SAME(refine.estimate_link_timing);
#undef SCP_SAME
}

TEST(Config, UnknownKeyNamesKeyLineAndAlternatives) {
  const std::string e = error_of("loop:\n  period_s: 0.001\n  perod: 2\n");
  EXPECT_NE(e.find("test.yaml:3"), std::string::npos) << e;
  EXPECT_NE(e.find("unknown key 'loop.perod'"), std::string::npos) << e;
  EXPECT_NE(e.find("period_s"), std::string::npos) << e;
}

TEST(Config, OutOfRangeNamesKeyLineAndRange) {
  const std::string e = error_of("estimator:\n  beta: 0\n");
  EXPECT_NE(e.find("test.yaml:2"), std::string::npos) << e;
  EXPECT_NE(e.find("estimator.beta"), std::string::npos) << e;
  EXPECT_NE(e.find("[0.001, 10000]"), std::string::npos) << e;
}

TEST(Config, WrongTypesAndBadYamlAreErrors) {
  EXPECT_NE(error_of("estimator:\n  beta: fast\n").find("'fast' is not a finite number"),
            std::string::npos);
  EXPECT_NE(error_of("estimator:\n  beta: .nan\n").find("not a finite number"), std::string::npos);
  EXPECT_NE(error_of("estimator:\n  theta0: [1, 2]\n").find("list of 6 numbers"),
            std::string::npos);
  EXPECT_NE(error_of("driver:\n  type: serial\n").find("one of sim|replay|modbus|can"),
            std::string::npos);
  EXPECT_NE(error_of("loop: [1, 2\n").find("not valid YAML"), std::string::npos);
  EXPECT_NE(error_of("- 1\n- 2\n").find("top level must be a mapping"), std::string::npos);
  EXPECT_NE(error_of("socket:\n  mode: rw\n").find("octal"), std::string::npos);
  EXPECT_NE(error_of("excitation:\n  sines:\n    - {amplitude_v: 1, frequency_hz: 0}\n")
                .find("excitation.sines[0].frequency_hz"),
            std::string::npos);
}

// Choices are read into enumerations: a name outside the table is refused with the key, the line
// and every allowed name; every allowed name reads as its own value.
TEST(Config, ChoicesAreEnumerationsThatNameTheAllowedValues) {
  const std::string e = error_of("recording:\n  compress: zstd\n");
  EXPECT_NE(e.find("test.yaml:2"), std::string::npos) << e;
  EXPECT_NE(e.find("recording.compress"), std::string::npos) << e;
  EXPECT_NE(e.find("'zstd' is not allowed; use one of none|gzip"), std::string::npos) << e;
  for (const auto& [value, name] : kVelocityMethods) {
    const auto cfg =
        load_config_text("driver: {velocity: {method: " + std::string(name) + "}}", "choice.yaml");
    EXPECT_EQ(cfg.driver.velocity.method, value) << name;
  }
  for (const auto& [value, name] : kLinkTimings) {
    const auto cfg =
        load_config_text("refine: {link_timing: " + std::string(name) + "}", "choice.yaml");
    EXPECT_EQ(cfg.refine.link_timing, value) << name;
  }
  for (const auto& [value, name] : kDriverTypes) {
    EXPECT_STREQ(to_string(value), name);
  }
}

TEST(Config, CrossKeyChecks) {
  EXPECT_NE(error_of("safety: {temperature_min_c: 50, temperature_max_c: 40}\n").find("below"),
            std::string::npos);
  EXPECT_NE(error_of("driver: {type: replay}\n").find("driver.replay.file"), std::string::npos);
  EXPECT_NE(error_of("estimator: {p0: 10, p_max: 1}\n").find("p_max"), std::string::npos);
}

// The two relations between health keys (each key's range is the Binder's): the error names the
// key that breaks it and its line.
TEST(Config, HealthCrossKeyChecks) {
  const std::string reference =
      error_of("health:\n  trend_span_s: 600\n  reference_span_s: 1200\n");
  EXPECT_NE(reference.find("health.reference_span_s"), std::string::npos) << reference;
  EXPECT_NE(reference.find("must not exceed health.trend_span_s"), std::string::npos) << reference;
  const std::string min_span = error_of(
      "health:\n  trend_span_s: 600\n  reference_span_s: 300\n"
      "  trend_min_span_s: 900\n");
  EXPECT_NE(min_span.find("health.trend_min_span_s"), std::string::npos) << min_span;
  EXPECT_EQ(error_of("health: {trend_span_s: 600, reference_span_s: 600, trend_min_span_s: 600}\n"),
            "(no error)");
}

// refine.nuisance.*: `estimate` (the default of the three output terms) frees the term, a number
// holds it there (in the fit's units); the sensor's lag is 0 unless refused.
TEST(Config, NuisanceTermsAreEstimatedOrHeld) {
  const DaemonConfig defaults = load_config_text("{}", "test.yaml");
  EXPECT_FALSE(defaults.refine.nuisance.x_zero.fixed);
  EXPECT_FALSE(defaults.refine.nuisance.ambient_offset.fixed);
  EXPECT_FALSE(defaults.refine.nuisance.ambient_drift.fixed);
  EXPECT_FALSE(defaults.refine.nuisance.sensor_lag.fixed);
  const DaemonConfig held = load_config_text(
      "refine: {nuisance: {x_zero: 2.0e-5, ambient_offset: estimate, ambient_drift: 3.6}}\n",
      "test.yaml");
  EXPECT_TRUE(held.refine.nuisance.x_zero.fixed);
  EXPECT_EQ(held.refine.nuisance.x_zero.value, 2.0e-5);
  EXPECT_FALSE(held.refine.nuisance.ambient_offset.fixed);
  EXPECT_TRUE(held.refine.nuisance.ambient_drift.fixed);
  EXPECT_DOUBLE_EQ(held.refine.nuisance.ambient_drift.value, 0.001);  // °C/h → °C/s
  const std::string word = error_of("refine: {nuisance: {x_zero: soon}}\n");
  EXPECT_NE(word.find("refine.nuisance.x_zero"), std::string::npos) << word;
  EXPECT_NE(word.find("`estimate`"), std::string::npos) << word;
  const std::string range = error_of("refine: {nuisance: {ambient_offset: 51}}\n");
  EXPECT_NE(range.find("out of range"), std::string::npos) << range;
  const DaemonConfig lag = load_config_text("refine: {nuisance: {sensor_lag: 0.2}}\n", "test.yaml");
  EXPECT_TRUE(lag.refine.nuisance.sensor_lag.fixed);
  EXPECT_EQ(lag.refine.nuisance.sensor_lag.value, 0.2);
  // The extensions load as off, on or auto; another word is refused naming the key.
  const DaemonConfig ext = load_config_text(
      "refine: {extensions: {cooling_tempco: auto, resistance_tempco: on}}\n", "test.yaml");
  EXPECT_EQ(ext.refine.extensions.cooling_tempco, scp::refine::ExtensionMode::automatic);
  EXPECT_EQ(ext.refine.extensions.resistance_tempco, scp::refine::ExtensionMode::on);
  EXPECT_EQ(ext.refine.extensions.stiffness_softening, scp::refine::ExtensionMode::off);
  const std::string bad = error_of("refine: {extensions: {cooling_tempco: maybe}}\n");
  EXPECT_NE(bad.find("refine.extensions.cooling_tempco"), std::string::npos) << bad;
}

// refine.voltage_interval is resolved once the driver is made: `auto` is before when the driver
// stamps when each voltage took effect, estimate when it does not (a replayed file without
// V_since); a stated interval is kept whatever the driver, and a declared before or after (a
// user's statement, perhaps a guess) is weighed against the data.
TEST(Config, VoltageIntervalIsResolvedByWhatTheDriverStamps) {
  using scp::refine::VoltageInterval;
  RefineSettings r;
  r.voltage_interval_choice = VoltageIntervalChoice::automatic;
  resolve_voltage_interval(r, true);
  EXPECT_EQ(r.voltage_interval, VoltageInterval::before);
  EXPECT_FALSE(r.check_declared_interval);
  resolve_voltage_interval(r, false);
  EXPECT_EQ(r.voltage_interval, VoltageInterval::estimate);
  EXPECT_FALSE(r.check_declared_interval);
  const std::pair<VoltageIntervalChoice, VoltageInterval> stated[] = {
      {VoltageIntervalChoice::before, VoltageInterval::before},
      {VoltageIntervalChoice::after, VoltageInterval::after},
      {VoltageIntervalChoice::estimate, VoltageInterval::estimate}};
  for (const auto& [choice, interval] : stated) {
    for (const bool stamps : {true, false}) {
      r.voltage_interval_choice = choice;
      resolve_voltage_interval(r, stamps);
      EXPECT_EQ(r.voltage_interval, interval) << static_cast<int>(choice) << stamps;
      EXPECT_EQ(r.check_declared_interval, interval != VoltageInterval::estimate);
    }
  }
}

// The refinement's window is preallocated: its size is checked against the period, and a fit
// needs min_window_s of it.
TEST(Config, RefineSection) {
  const DaemonConfig defaults = load_config_text("{}", "test.yaml");
  EXPECT_TRUE(defaults.refine.enabled);
  EXPECT_EQ(defaults.refine.window_s, 300.0);
  EXPECT_EQ(defaults.refine.interval_s, 10.0);
  EXPECT_EQ(defaults.refine.min_window_s, 30.0);
  EXPECT_NE(error_of("refine: {min_window_s: 400}\n").find("must not exceed refine.window_s"),
            std::string::npos);
  const std::string big = error_of("loop: {period_s: 0.0001}\nrefine: {window_s: 200}\n");
  EXPECT_NE(big.find("2000000 samples"), std::string::npos) << big;
  EXPECT_NE(big.find("shorten refine.window_s"), std::string::npos) << big;
  // Disabled, the window is never allocated, so its size does not matter.
  EXPECT_EQ(error_of("loop: {period_s: 0.0001}\nrefine: {enabled: false, window_s: 200}\n"),
            "(no error)");
  EXPECT_NE(error_of("refine: {hac_lags: -1}\n").find("refine.hac_lags"), std::string::npos);
  EXPECT_NE(error_of("refine: {covariance_batches: 1001}\n").find("refine.covariance_batches"),
            std::string::npos);
}

// estimator.known: six entries, each 0 (estimated) or 1 (known, held at theta0).
TEST(Config, KnownParametersAreZeroOrOne) {
  const auto cfg = load_config_text("estimator:\n  known: [0, 0, 1, 0, 0, 0]\n", "test.yaml");
  for (std::size_t i = 0; i < 6; ++i) EXPECT_EQ(cfg.estimator.known[i], i == 2) << i;
  const auto none = load_config_text("", "test.yaml");
  for (std::size_t i = 0; i < 6; ++i) EXPECT_FALSE(none.estimator.known[i]) << i;

  // 2: outside [0, 1], refused by the list's range check, naming the entry.
  std::string e = error_of("estimator:\n  known: [0, 0, 2, 0, 0, 0]\n");
  EXPECT_NE(e.find("test.yaml:2"), std::string::npos) << e;
  EXPECT_NE(e.find("estimator.known[2]"), std::string::npos) << e;
  EXPECT_NE(e.find("[0, 1]"), std::string::npos) << e;
  // 0.5: in range but neither 0 nor 1.
  e = error_of("estimator:\n  known: [0, 0, 0.5, 0, 0, 0]\n");
  EXPECT_NE(e.find("estimator.known"), std::string::npos) << e;
  EXPECT_NE(e.find("known[2] is 0.5"), std::string::npos) << e;
  EXPECT_NE(e.find("0.5"), std::string::npos) << e;
  EXPECT_NE(error_of("estimator:\n  known: [0, 0, 1]\n").find("list of 6 numbers"),
            std::string::npos);
  EXPECT_NE(error_of("estimator:\n  known: [0, 0, yes, 0, 0, 0]\n").find("estimator.known[2]"),
            std::string::npos);
}

TEST(Config, MechanicalForgetting) {
  EXPECT_EQ(load_config_text("", "test.yaml").estimator.forgetting_mechanical, 0.0);
  const auto cfg = load_config_text("estimator:\n  forgetting_mechanical: 0.05\n", "test.yaml");
  EXPECT_EQ(cfg.estimator.forgetting_mechanical, 0.05);
  const std::string e = error_of("estimator:\n  forgetting_mechanical: -0.1\n");
  EXPECT_NE(e.find("test.yaml:2"), std::string::npos) << e;
  EXPECT_NE(e.find("estimator.forgetting_mechanical"), std::string::npos) << e;
}

TEST(Config, ReferenceListsEveryDeclaredKeyOnce) {
  const std::string ref = config_reference_markdown();
  for (const char* key : {"`loop.period_s`", "`estimator.beta`",
                          "`excitation.sines[].frequency_hz`", "`safety.temperature_max_c`",
                          "`socket.path`", "`state.warm_start`", "`driver.sim.plant.b`"}) {
    const auto first = ref.find(key);
    EXPECT_NE(first, std::string::npos) << key;
    EXPECT_EQ(ref.find(key, first + 1), std::string::npos) << key << " declared twice";
  }
}

// Issue 11: yaml-cpp keeps both entries of a repeated key and lookups take the first, so the
// second `loop:` was ignored without a word.
TEST(Config, DuplicateKeysAreErrorsNamingBothLines) {
  std::string e = error_of("loop: {period_s: 0.001}\nloop: {period_s: 0.01}\n");
  EXPECT_NE(e.find("test.yaml:2: duplicate key 'loop' (first at line 1)"), std::string::npos) << e;
  e = error_of("estimator:\n  beta: 3\n  forgetting: 1\n  beta: 4\n");
  EXPECT_NE(e.find("test.yaml:4: duplicate key 'estimator.beta' (first at line 2)"),
            std::string::npos)
      << e;
  // The same name in different sections is not a duplicate.
  EXPECT_EQ(error_of("driver:\n  sim:\n    drift: {m: 0}\n    plant: {m: 0.1}\n"), "(no error)");
}

// Issue 11's text slips in the declarations (the reference, docs and man page show them).
TEST(Config, ReferenceTextSlips) {
  const std::string ref = config_reference_markdown();
  EXPECT_EQ(ref.find("0 = forgetting."), std::string::npos);
  EXPECT_NE(ref.find("0 = use estimator.forgetting"), std::string::npos);
  for (const char* name : {"x", "xdot", "temperature", "voltage"}) {
    const std::string key = std::string("`driver.can.") + name + ".stale_timeout_s`";
    const auto row = ref.find(key);
    ASSERT_NE(row, std::string::npos) << key;
    const std::string line = ref.substr(row, ref.find('\n', row) - row);
    EXPECT_NE(line.find(std::string("\"CAN signal ") + name + " stale\""), std::string::npos)
        << line;
  }
}

TEST(Config, ManPageListsEveryKeyOfTheReference) {
  const std::string man = config_reference_man("9.9");
  EXPECT_EQ(man.rfind(".TH SCP\\-ESTIMATOR.YAML 5 \"\" \"scp-estimator 9.9\"", 0), 0U)
      << man.substr(0, 80);
  Binder doc = Binder::documenting();
  DaemonConfig defaults;
  declare_daemon_keys(doc, defaults);
  std::size_t keys = 0;
  for (const auto& key : doc.docs()) {
    std::string escaped;
    for (const char c : key.path) escaped += c == '-' ? std::string("\\-") : std::string(1, c);
    const bool top_section = key.type == "section" && key.path.find('.') == std::string::npos;
    const std::string shown = top_section ? ".SS " + escaped + "\n" : "\\fB" + escaped + "\\fR";
    EXPECT_NE(man.find(shown), std::string::npos) << key.path;
    ++keys;
  }
  EXPECT_GT(keys, 100U);
}

TEST(Config, StartupFindingsOfASoundConfigAreEmptyAndSuspiciousValuesWarn) {
  auto cfg = load_config_text("state: {directory: /tmp}\n", "test.yaml");
  EXPECT_TRUE(startup_findings(cfg).empty());
  cfg = load_config_text(
      "state: {directory: /tmp}\nsafety: {temperature_max_c: 373, voltage_max_v: 3.3}\n"
      "excitation: {profile: custom, v_max: 5}\n",
      "test.yaml");
  const auto findings = startup_findings(cfg);
  ASSERT_EQ(findings.size(), 2U);
  EXPECT_EQ(findings[0].severity, Finding::Severity::warning);
  EXPECT_EQ(findings[0].key, "safety.temperature_max_c");
  EXPECT_EQ(findings[1].key, "excitation.v_max");
}

}  // namespace
}  // namespace scp::config

namespace scp::config {
namespace {

// docs/configuration.md is the reference's output, so the documentation cannot go stale.
TEST(Config, DocumentationMatchesTheDeclarations) {
  std::ifstream in(std::string(SCP_SOURCE_DIR) + "/docs/configuration.md");
  ASSERT_TRUE(in) << "docs/configuration.md is missing";
  std::stringstream text;
  text << in.rdbuf();
  EXPECT_EQ(text.str(), config_reference_markdown())
      << "docs/configuration.md is stale: regenerate it with\n"
         "  build/daemon/scp-estimatord --print-config-reference > docs/configuration.md";
}

}  // namespace
}  // namespace scp::config
