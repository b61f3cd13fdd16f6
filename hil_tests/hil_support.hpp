#pragma once
// What the end-to-end tests against the real daemon share: bounded polling of
// a condition, the daemon's journal as JSON, and the fixture that starts the
// daemon and connects the ground to it (DaemonTest).

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <csignal>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Core>

#include "foresight/common/object_model.hpp"
#include "foresight/common/plan.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/ground_link/ground_link.hpp"
#include "foresight/protocol/loopback.hpp"
#include "foresight/test/cli.hpp"
#include "foresight/test/eventually.hpp"
#include "foresight/test/remote_process.hpp"

namespace foresight::test {


/// `foresight-remote journal --json --db DB`, parsed. A failed run or output
/// that is not a JSON object is a test failure (and an empty object).
inline nlohmann::json journal_json(const std::string& db) {
  const CliRun r = run_program("foresight-remote", "journal --json --db " + db);
  EXPECT_EQ(r.status, 0) << r.err;
  auto j = nlohmann::json::parse(r.out, nullptr, false);
  if (j.is_discarded() || !j.is_object()) {
    ADD_FAILURE() << "journal of " << db << " is not a JSON object: " << r.out.substr(0, 400);
    return nlohmann::json::object();
  }
  return j;
}

/// The arm's joint angles as the ground last received them (within 10 s);
/// a test failure and zeros when none arrive.
inline Eigen::VectorXd current_q(const ground_link::GroundLink& ground) {
  Eigen::VectorXd q = Eigen::VectorXd::Zero(7);
  const bool ok = eventually(
      [&] {
        const auto js = ground.joint_state();
        if (!js || js->value.q_rad.size() != 7) return false;
        q = Eigen::Map<const Eigen::VectorXd>(js->value.q_rad.data(), 7);
        return true;
      },
      std::chrono::seconds(10));
  EXPECT_TRUE(ok) << "no joint state";
  return q;
}

/// Sends a slow GOTO_JOINT (10% speed) of joint 1 by `delta` from `q0`;
/// returns its command id once the remote reports it EXECUTING (within 5 s).
inline std::uint64_t start_slow_motion(ground_link::GroundLink& ground, const Eigen::VectorXd& q0, double delta) {
  protocol::GotoJoint g;
  g.q_rad.assign(q0.data(), q0.data() + 7);
  g.q_rad[0] += delta;
  g.speed_fraction = 0.1;
  const std::uint64_t id = ground.send(protocol::CommandKind::GotoJoint, g);
  const bool executing = eventually(
      [&] {
        const auto partial = ground.wait_final(id, std::chrono::milliseconds(0));
        for (const auto& a : partial.acks)
          if (a.state == protocol::AckState::Executing) return true;
        return false;
      },
      std::chrono::seconds(5));
  EXPECT_TRUE(executing) << "command " << id << " never EXECUTING";
  return id;
}

/// The set-up every test against the real daemon shares: DDS on loopback, a
/// DDS domain this process has claimed (protocol::unique_test_domain: a lock
/// The simulated drives' own record (`--sim-faults DIR`: DIR/drive_record,
/// sim_faults.hpp): what the drives did, not what the master believes.
struct DriveRecord {
  std::uint64_t seq = 0, marks = 0;
  std::vector<double> q, lo, hi;            ///< joint angles now, lowest and highest since the mark (rad)
  std::vector<std::string> state;           ///< CiA 402 state per joint, as the drive holds it (snake case)
  std::vector<bool> powered;                ///< power stage energised
  std::vector<unsigned> states_seen;        ///< bit per CiA 402 state value since the mark
  double span(std::size_t j) const { return hi[j] - lo[j]; }
  /// The drive was in `state_value` (CiA 402 order: 4 operation enabled, 5 quick stop active) since the mark.
  bool was_in(std::size_t j, unsigned state_value) const { return (states_seen[j] >> state_value) & 1u; }
};

/// Parses DIR/drive_record; seq 0 when it is missing or incomplete.
inline DriveRecord read_drive_record(const std::string& dir, std::size_t joints = 7) {
  DriveRecord r;
  std::ifstream in(dir + "/drive_record");
  std::string line, power;
  if (!std::getline(in, line) || !std::getline(in, power)) return r;
  std::istringstream s(line);
  std::vector<double> v;
  double x;
  if (!(s >> r.seq >> r.marks)) return DriveRecord{};
  while (s >> x) v.push_back(x);
  if (v.size() != 3 * joints) return DriveRecord{};
  r.q.assign(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(joints));
  r.lo.assign(v.begin() + static_cast<std::ptrdiff_t>(joints), v.begin() + static_cast<std::ptrdiff_t>(2 * joints));
  r.hi.assign(v.begin() + static_cast<std::ptrdiff_t>(2 * joints), v.end());
  std::istringstream p(power);
  std::string word;
  if (!(p >> word) || word != "power") return DriveRecord{};
  for (std::size_t j = 0; j < joints; ++j) {
    std::string name;
    int on = 0;
    unsigned seen = 0;
    if (!(p >> name >> on >> seen)) return DriveRecord{};
    r.state.push_back(name);
    r.powered.push_back(on != 0);
    r.states_seen.push_back(seen);
  }
  return r;
}

/// file, so no concurrent test shares it), `foresight-remote --sim` started
/// on it (test::RemoteProcess, ready within 60 s) and the ground's link
/// connected to it (the remote seen within 30 s); at the end the link closed
/// and the daemon stopped with SIGTERM, its exit status 0.
///
/// A derived fixture adjusts `remote_options_` and `ground_config_` (or calls
/// use_sim_faults()) before it calls DaemonTest::SetUp(); their domain is
/// always this test's.
class DaemonTest : public ::testing::Test {
 protected:
  void SetUp() override {
    protocol::use_loopback_if_unconfigured();
    domain_ = static_cast<int>(protocol::unique_test_domain());
    ASSERT_NO_FATAL_FAILURE(start_remote(remote_options_));
    ASSERT_NO_FATAL_FAILURE(connect_ground());
  }
  void TearDown() override {
    ground_.reset();
    if (remote_) {
      const int rc = remote_->stop(SIGTERM);
      EXPECT_EQ(rc, 0) << remote_->log();
    }
    if (!faults_.empty()) std::filesystem::remove_all(faults_);
    if (!config_dir_.empty()) std::filesystem::remove_all(config_dir_);
  }

  /// Starts (or restarts) the daemon with `options` on this test's domain and
  /// waits for its ready line.
  void start_remote(test::RemoteProcess::Options options) {
    options.domain = domain_;
    remote_ = std::make_unique<test::RemoteProcess>(std::move(options));
    ASSERT_TRUE(remote_->ready()) << remote_->log();
  }
  /// A fresh ground link (`ground_config_`) on this test's domain, once it
  /// sees the remote and the remote hears its heartbeats (30 s each).
  ///
  /// wait_for_remote() covers the command and upload topics and a ping; the
  /// ground's heartbeats are a topic of their own, matched on their own: in
  /// two loaded LinkLoss runs the remote heard none in the ~1 s between the
  /// connection and the test pausing them (their journals: the first
  /// link_regained only when they resumed, 16.7 and 17.1 s after the start),
  /// so it never had a link to lose. The remote logs "remote link: link up"
  /// when it first hears one.
  void connect_ground() {
    ground_link::Config c = ground_config_;
    c.domain = domain_;
    ground_ = std::make_unique<ground_link::GroundLink>(c);
    ASSERT_TRUE(ground_->wait_for_remote(std::chrono::seconds(30))) << "no remote on DDS domain " << domain_;
    ASSERT_TRUE(eventually([&] { return remote_->log().find("remote link: link up") != std::string::npos; },
                           std::chrono::seconds(30)))
        << "the remote never heard the ground's heartbeat\n"
        << remote_->log();
  }

  /// Restarts the daemon on the shipped configuration with `key` (text in
  /// config/remote.yaml) replaced by `replacement`, in a folder of its own
  /// beside the other shipped files (the URDF, the scene, the drive files:
  /// read from the configuration's folder); a new ground link to it.
  void restart_remote_with(const std::string& key, const std::string& replacement) {
    std::string yaml = test::read_file(FORESIGHT_CONFIG_DIR "/remote.yaml");
    const auto at = yaml.find(key);
    ASSERT_NE(at, std::string::npos) << "config/remote.yaml has no '" << key << "'";
    yaml.replace(at, key.size(), replacement);
    config_dir_ = test::temp_path(".config");  // removed at the end of the test
    std::filesystem::create_directories(config_dir_);
    for (const auto& e : std::filesystem::directory_iterator(FORESIGHT_CONFIG_DIR))
      if (e.path().filename() != "remote.yaml")
        std::filesystem::create_symlink(e.path(), std::filesystem::path(config_dir_) / e.path().filename());
    const std::string path = config_dir_ + "/remote.yaml";
    std::ofstream(path) << yaml;
    ground_.reset();
    ASSERT_EQ(remote_->stop(SIGTERM), 0) << remote_->log();
    test::RemoteProcess::Options o = remote_options_;
    o.config = path;
    ASSERT_NO_FATAL_FAILURE(start_remote(o));
    ASSERT_NO_FATAL_FAILURE(connect_ground());
  }

  /// The daemon's simulated faults from a folder (`--sim-faults`): a file
  /// there switches its fault on (sim_faults.hpp). Call before SetUp().
  void use_sim_faults() {
    faults_ = test::temp_path(".faults");
    remote_options_.extra_args.push_back("--sim-faults");
    remote_options_.extra_args.push_back(faults_);
  }
  void fault_on(const std::string& name, const std::string& text = "\n") {
    std::ofstream(faults_ + "/" + name) << text;
  }
  void fault_off(const std::string& name) { std::filesystem::remove(faults_ + "/" + name); }

  /// The simulated drives' own record (use_sim_faults()).
  DriveRecord record() const { return read_drive_record(faults_); }
  /// Starts a new envelope on the drives' record; returns once it is in force.
  void mark() {
    const std::uint64_t m = record().marks;
    std::ofstream(faults_ + "/drive_record_mark") << "\n";
    ASSERT_TRUE(eventually([&] { return record().marks > m; }, std::chrono::seconds(10))) << "the mark was never taken";
  }
  /// The record written after now (two polls later: the envelope covers everything until now).
  DriveRecord fresh_record() {
    const std::uint64_t s = record().seq;
    DriveRecord r;
    EXPECT_TRUE(eventually([&] { return (r = record()).seq >= s + 2; }, std::chrono::seconds(10)));
    return r;
  }

  /// One command and its final answer (`expected_s`: how long it should take);
  /// every result also goes to after_command().
  ground_link::CommandResult run(protocol::CommandKind kind, const protocol::Payload& payload = protocol::NoPayload{},
                                 double expected_s = 2.0) {
    auto r = ground_->execute(kind, payload, expected_s);
    after_command(r);
    return r;
  }
  /// A fixture that keeps a record of what it sent overrides this.
  virtual void after_command(const ground_link::CommandResult&) {}

  /// Take control and enable the drives.
  void take_and_recover() {
    const auto take = run(protocol::CommandKind::TakeControl);
    ASSERT_TRUE(take.succeeded()) << take.reason;
    const auto rec = run(protocol::CommandKind::Recover, protocol::NoPayload{}, 5.0);
    ASSERT_TRUE(rec.succeeded()) << rec.reason << "\n" << remote_->log();
  }

  Eigen::VectorXd current_q() { return test::current_q(*ground_); }
  /// A slow GOTO_JOINT of joint 1 by `delta` from `q0` (or from where the arm
  /// is); its id once EXECUTING.
  std::uint64_t start_slow_motion(const Eigen::VectorXd& q0, double delta) {
    return test::start_slow_motion(*ground_, q0, delta);
  }
  std::uint64_t start_slow_motion(double delta) { return start_slow_motion(current_q(), delta); }
  /// Waits (at most 10 s) until the remote reports command `id` QUEUED.
  bool wait_queued(std::uint64_t id) {
    return eventually(
        [&] {
          for (const auto& ack : ground_->wait_final(id, std::chrono::milliseconds(0)).acks)
            if (ack.state == protocol::AckState::Queued) return true;
          return false;
        },
        std::chrono::seconds(10));
  }
  /// A plan from the arm's joints to 1 cm in front of the ORU's bore at the work
  /// site's true pose: to approach_20cm, then straight along the hole's axis.
  Trajectory plan_to_before_the_bore() {
    const ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
    const Scene scene = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml");
    const auto tag_goal = [&](const std::string& name, SegmentKind kind, double dz) {
      Goal g;
      g.name = name;
      g.kind = kind;
      g.is_pose = true;
      g.base_T_tip = scene.base_T_object * oru.tags.at(name) * Pose(Eigen::Translation3d(0.0, 0.0, dz));
      return g;
    };
    return plan_motion(model_, current_q(),
                       {tag_goal("approach_20cm", SegmentKind::Joint, 0.0),
                        tag_goal("hole_entrance", SegmentKind::Linear, -0.01)})
        .trajectory;
  }

  /// The running (or stopped) daemon's journal.
  nlohmann::json journal_json() const { return test::journal_json(remote_->journal()); }

  RobotModel model_ = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  test::RemoteProcess::Options remote_options_;
  ground_link::Config ground_config_;
  std::string config_dir_;  ///< restart_remote_with()'s configuration folder
  int domain_ = 0;
  std::string faults_;  ///< the --sim-faults folder ("" = none)
  std::unique_ptr<test::RemoteProcess> remote_;
  std::unique_ptr<ground_link::GroundLink> ground_;
};

}  // namespace foresight::test
