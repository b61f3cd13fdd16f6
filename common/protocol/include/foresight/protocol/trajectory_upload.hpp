#pragma once
// A whole-trajectory upload: the ground splits a trajectory into
// TrajectoryChunks; the remote assembles them per trajectory_id, and only when
// every chunk arrived does it validate the whole (structure, then the
// trajectory rules and the SHA-256 content hash of common/trajectory), commit
// it, and let a TRAJECTORY command run it. docs/protocol.md has the flow.
//
// Not real-time: everything here allocates.

#include <chrono>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "foresight/common/trajectory.hpp"
#include "foresight/protocol/dds.hpp"
#include "foresight/protocol/messages.hpp"

namespace foresight::protocol {

/// Splits `trajectory` into chunks of at most `max_samples_per_chunk` samples
/// (0 = as many as fit in MAX_CHUNK_VALUES doubles). Every chunk carries the
/// whole's id, sizes and `hash` (normally trajectory_hash(trajectory)).
/// Throws std::invalid_argument when the trajectory is empty, has no or more
/// than MAX_JOINTS joints, or needs more than MAX_CHUNKS chunks.
std::vector<Sample<msg::TrajectoryChunk>> make_chunks(const Trajectory& trajectory, std::uint64_t trajectory_id,
                                                      std::uint64_t session_id, const TrajectoryHash& hash,
                                                      std::uint32_t max_samples_per_chunk = 0);
/// As above with hash = trajectory_hash(trajectory).
std::vector<Sample<msg::TrajectoryChunk>> make_chunks(const Trajectory& trajectory, std::uint64_t trajectory_id,
                                                      std::uint64_t session_id,
                                                      std::uint32_t max_samples_per_chunk = 0);

/// A trajectory that arrived whole (structure checked; content not yet).
struct AssembledTrajectory {
  std::uint64_t trajectory_id = 0;
  std::uint64_t session_id = 0;
  Trajectory trajectory;
  TrajectoryHash declared_hash{};  ///< the hash the chunks carried
};

/// Collects chunks per trajectory_id. A chunk that contradicts the upload's
/// first chunk (sizes, hash), is out of range, or overlaps samples already
/// received rejects the whole upload; later chunks of a rejected upload keep
/// being rejected until discard(). An exact duplicate of a received chunk is
/// ignored (a ground that re-sends after a restart does no harm).
class TrajectoryAssembler {
 public:
  struct Limits {
    std::uint32_t max_joints = msg::kMaxJoints;
    std::uint32_t max_samples = 200000;  ///< as TrajectoryLimits::max_samples
    std::size_t max_pending = 4;         ///< uploads assembling at the same time
    /// Of them, from one session (another session's half uploads cannot take every slot).
    std::size_t max_pending_per_session = 4;
  };

  /// What add() did; `state` is UPLOAD_ASSEMBLING, UPLOAD_COMMITTED (here:
  /// "whole", ready for take() and verification) or UPLOAD_REJECTED.
  struct Progress {
    std::uint64_t trajectory_id = 0;
    msg::UploadState state = msg::UploadState{};
    std::uint32_t chunks_received = 0;
    std::uint32_t chunk_count = 0;
    msg::ReasonCode code = msg::ReasonCode{};
    std::string reason;  ///< names the chunk and the field when rejected
    bool whole() const noexcept;
  };

  TrajectoryAssembler();
  explicit TrajectoryAssembler(Limits limits);

  Progress add(const msg::TrajectoryChunk& chunk);
  /// Removes and returns the upload once it is whole; nullopt otherwise.
  std::optional<AssembledTrajectory> take(std::uint64_t trajectory_id);
  /// Forgets an upload (assembling or rejected).
  void discard(std::uint64_t trajectory_id);
  std::size_t pending() const noexcept { return uploads_.size(); }
  /// Rejects (REASON_INCOMPLETE_UPLOAD, "no chunk for N s: k of n chunks
  /// arrived") every upload still assembling whose last chunk came more than
  /// `idle` before `now`, frees its data and returns their progress.
  std::vector<Progress> expire(std::chrono::steady_clock::time_point now, std::chrono::nanoseconds idle);
  /// Sample values held for uploads being assembled: what arrived, never what
  /// a first chunk declared.
  std::size_t values_held() const noexcept;

 private:
  struct Upload {
    std::uint64_t session_id = 0;
    std::uint32_t chunk_count = 0;
    std::uint32_t joint_count = 0;
    std::uint32_t sample_count = 0;
    TrajectoryHash hash{};
    /// Per chunk index: its values as they arrived (t_s, q...; row-major),
    /// empty until then. Memory follows what arrived, not what was declared.
    std::vector<std::vector<double>> chunk_values;
    std::chrono::steady_clock::time_point last_chunk{};
    std::vector<bool> chunk_received;  ///< per chunk index
    std::vector<bool> sample_covered;  ///< per sample
    std::vector<std::uint32_t> chunk_first, chunk_samples;  ///< per chunk index, for duplicates
    std::uint32_t chunks_received = 0;
    bool rejected = false;
    msg::ReasonCode code{};
    std::string reason;
  };
  Progress progress(std::uint64_t id, const Upload& upload) const;
  Progress reject(std::uint64_t id, Upload& upload, msg::ReasonCode code, std::string reason);

  Limits limits_;
  std::map<std::uint64_t, Upload> uploads_;
};

/// The remote's verdict on an assembled trajectory: REASON_NONE when the
/// content hash matches the declared one and validate() finds nothing;
/// otherwise REASON_HASH_MISMATCH (both hashes in hex) or
/// REASON_VALIDATION_FAILED (the first violations, with row and joint).
struct UploadVerdict {
  msg::ReasonCode code = msg::ReasonCode{};
  std::string reason;
  TrajectoryHash computed_hash{};
  std::vector<Violation> violations;
  bool ok() const noexcept;
};
UploadVerdict verify(const AssembledTrajectory& assembled, const TrajectoryLimits& limits);

/// Copies a hash into / out of the IDL's octet[32].
void set_hash(msg::Sha256& field, const TrajectoryHash& hash) noexcept;
TrajectoryHash get_hash(const msg::Sha256& field) noexcept;

}  // namespace foresight::protocol
