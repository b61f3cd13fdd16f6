#pragma once
// `foresight run`'s command runner: each task-script command (script.hpp)
// carried out on the ground and, for the remote ones, over the link. CALIBRATE,
// LOCALIZE and the preview rendering call the operations the commands
// `foresight calibrate|localize|synth|preview` call (operations.hpp), in this
// process, so the run does exactly what those commands do; planning is common
// plan_motion. Not real-time code.

#include <Eigen/Core>
#include <chrono>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/ground_link/ground_link.hpp"
#include "foresight/script/executor.hpp"

namespace foresight::session {

struct RunSettings {
  std::string work_dir = ".";     ///< trajectories, previews, cameras.yaml, localize.json, run.jsonl
  std::string robot, object, scene;
  std::string cameras;            ///< cameras.yaml (CALIBRATE writes work/cameras.yaml)
  std::string image;              ///< video frame for previews ("": synthesized by `foresight synth`)
  std::string object_pose;        ///< localize JSON, "scene" (the work site's true pose) or ""
  bool preview = true;            ///< render every TRAJECTORY / PREVIEW
  double preview_speed = 4.0;     ///< preview playback speed
  bool dry_run = false;           ///< nothing sent; the simulated arm follows the plan
  Eigen::VectorXd q_from;         ///< dry run: the start joints
  double timeout_s = 0.0;         ///< final-ack override (0: derived from the delay)
  bool quiet = false;             ///< --json: progress goes to stderr
  bool recover = false;           ///< send RECOVER after taking control (drives on, hold)
  bool chain = false;             ///< --chain: motions sent ahead as a chain (after_command_id), not waited for
  /// CHECK steps the operator overrides by name (`run --override-check
  /// insert`): a no_go is journaled as overridden and the run goes on.
  std::vector<std::string> override_checks;
  std::string ground;             ///< ground.yaml (CHECK: its contact_check section)
};

class ScriptRunner : public script::CommandRunner {
 public:
  /// Loads the models; with a link, takes control of the remote (and RECOVERs
  /// when asked): LinkFailure when that is refused. Gives control back at the end.
  ScriptRunner(RunSettings settings, std::unique_ptr<ground_link::GroundLink> link);
  ~ScriptRunner() override;
  ScriptRunner(const ScriptRunner&) = delete;
  ScriptRunner& operator=(const ScriptRunner&) = delete;
  script::Outcome run(const script::Command& command, const std::function<bool()>& interrupted) override;
  /// --chain: TRAJECTORY, INVOKE_ALGORITHM (but guarded_move, and insert or
  /// pull_out without their distance), the GOTOs, REQUEST and the display commands.
  bool chains(const script::Command& command) const override;
  void settle(const std::function<bool()>& interrupted,
              const std::function<void(int line, const script::Outcome&)>& on_settled) override;

  /// The configuration a script is checked against (tags, cameras, objects,
  /// joint count and limits), before anything connects.
  static script::ScriptContext context_for(const RobotModel& model, const ObjectModel& object, const Scene& scene);
  const Eigen::VectorXd& q_current() const { return q_; }

 private:
  script::Outcome local(const script::Command& c, const std::function<bool()>& interrupted);
  script::Outcome trajectory(const script::Command& c, bool send, const std::function<bool()>& interrupted);
  script::Outcome remote(const script::Command& c, const std::function<bool()>& interrupted);
  /// The paper's update step: the simulated arm takes the reported joints;
  /// returns the journal fields comparing them with the predicted ones.
  /// The paper's update step: the reported final joints become the simulated
  /// arm's. `completed` false (canceled, failed): the motion ended short of
  /// its planned end, and the line says so instead of reporting a difference.
  /// --chain: sends a motion after the last one sent ahead; the arm is then
  /// taken to be at `predicted` (the next is planned from there).
  script::Outcome send_ahead(const script::Command& c, protocol::CommandKind kind, std::uint64_t command_id,
                             std::chrono::steady_clock::time_point sent, double expected_s,
                             const Eigen::VectorXd& predicted, const std::string& what);
  /// Where an INVOKE_ALGORITHM leaves the arm when it succeeds: insert moves the
  /// tool tip depth_m along its own z axis, pull_out distance_m back; the others
  /// do not move it. nullopt when that is not known (guarded_move).
  std::optional<Eigen::VectorXd> algorithm_end(const script::Command& c);
  nlohmann::json update_arm(const std::vector<double>& reported, const Eigen::VectorXd& predicted,
                            bool completed = true);
  std::string path(const std::string& name) const;
  /// The ground.yaml in use (--ground, else the shipped one).
  std::string ground_yaml() const;
  void say(const std::string& line) const;
  void journal(const script::Command& c, const script::Outcome& o, nlohmann::json extra);

  RunSettings s_;
  std::unique_ptr<ground_link::GroundLink> link_;
  RobotModel model_;
  ObjectModel object_;
  Scene scene_;
  KinematicsWorkspace ws_;
  Eigen::VectorXd q_, q_start_;
  std::optional<Pose> base_T_object_;
  std::string pose_source_;
  /// The object pose file base_T_object_ came from ("": the scene's true
  /// pose, known exactly): CHECK reads its covariance.
  std::string pose_file_;
  script::Outcome check(const script::Command& c);
  std::string video_camera_, graphics_ = "hidden", frame_ = "world", tag_;
  bool grabbed_ = false;
  bool recover_before_next_ = false;  ///< a cancel stopped the arm (category 2): RECOVER before moving again
  int motion_count_ = 0;
  std::ofstream journal_;
  nlohmann::json pending_journal_;
  struct SentAhead {  ///< a command sent in the chain, its end not known yet
    script::Command command;
    protocol::CommandKind kind;
    std::uint64_t command_id = 0;
    std::chrono::steady_clock::time_point sent;
    double expected_s = 0.0;
    Eigen::VectorXd predicted;
    nlohmann::json journal;
  };
  std::vector<SentAhead> sent_ahead_;
  std::uint64_t chain_tail_ = 0;  ///< the last command sent ahead (0: nothing outstanding)
};

}  // namespace foresight::session
