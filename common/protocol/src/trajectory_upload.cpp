#include "foresight/protocol/trajectory_upload.hpp"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <sstream>
#include <stdexcept>

#include "foresight/protocol/codec.hpp"

namespace foresight::protocol {

void set_hash(msg::Sha256& field, const TrajectoryHash& hash) noexcept {
  std::memcpy(field, hash.data(), hash.size());
}

TrajectoryHash get_hash(const msg::Sha256& field) noexcept {
  TrajectoryHash hash;
  std::memcpy(hash.data(), field, hash.size());
  return hash;
}

std::vector<Sample<msg::TrajectoryChunk>> make_chunks(const Trajectory& trajectory, std::uint64_t trajectory_id,
                                                      std::uint64_t session_id, std::uint32_t max_samples_per_chunk) {
  return make_chunks(trajectory, trajectory_id, session_id, trajectory_hash(trajectory), max_samples_per_chunk);
}

std::vector<Sample<msg::TrajectoryChunk>> make_chunks(const Trajectory& trajectory, std::uint64_t trajectory_id,
                                                      std::uint64_t session_id, const TrajectoryHash& hash,
                                                      std::uint32_t max_samples_per_chunk) {
  const int samples = trajectory.samples();
  const int joints = trajectory.joints();
  if (samples < 1) throw std::invalid_argument("make_chunks: the trajectory has no samples");
  if (trajectory.positions_rad.rows() != samples) {
    throw std::invalid_argument("make_chunks: " + std::to_string(samples) + " times but " +
                                std::to_string(trajectory.positions_rad.rows()) + " rows of joint angles");
  }
  if (joints < 1 || joints > static_cast<int>(msg::kMaxJoints)) {
    throw std::invalid_argument("make_chunks: " + std::to_string(joints) + " joints; the protocol carries 1 to " +
                                std::to_string(msg::kMaxJoints));
  }
  const std::uint32_t row = static_cast<std::uint32_t>(joints) + 1;
  const std::uint32_t fit = msg::kMaxChunkValues / row;
  const std::uint32_t per_chunk = max_samples_per_chunk == 0 ? fit : std::min(fit, max_samples_per_chunk);
  const auto total = static_cast<std::uint32_t>(samples);
  const std::uint32_t count = (total + per_chunk - 1) / per_chunk;
  if (count > msg::kMaxChunks) {
    throw std::invalid_argument("make_chunks: " + std::to_string(samples) + " samples need " + std::to_string(count) +
                                " chunks; the protocol allows " + std::to_string(msg::kMaxChunks));
  }
  const std::int64_t issued = now_ns();
  std::vector<Sample<msg::TrajectoryChunk>> chunks(count);
  std::vector<double> values;
  for (std::uint32_t c = 0; c < count; ++c) {
    msg::TrajectoryChunk& chunk = *chunks[c];
    const std::uint32_t first = c * per_chunk;
    const std::uint32_t n = std::min(per_chunk, total - first);
    chunk.trajectory_id = trajectory_id;
    chunk.session_id = session_id;
    chunk.chunk_index = c;
    chunk.chunk_count = count;
    chunk.joint_count = static_cast<std::uint32_t>(joints);
    chunk.sample_count = total;
    chunk.first_sample = first;
    set_hash(chunk.content_hash, hash);
    chunk.issued_ns = issued;
    values.resize(static_cast<std::size_t>(n) * row);
    for (std::uint32_t i = 0; i < n; ++i) {
      const int s = static_cast<int>(first + i);
      values[i * row] = trajectory.time_s[static_cast<std::size_t>(s)];
      for (int j = 0; j < joints; ++j) values[i * row + 1 + static_cast<std::uint32_t>(j)] = trajectory.positions_rad(s, j);
    }
    assign(chunk.samples, std::span<const double>(values), msg::kMaxChunkValues, "trajectory chunk samples");
  }
  return chunks;
}

bool TrajectoryAssembler::Progress::whole() const noexcept {
  return state == foresight_msg_UPLOAD_COMMITTED;
}

TrajectoryAssembler::TrajectoryAssembler() : TrajectoryAssembler(Limits{}) {}
TrajectoryAssembler::TrajectoryAssembler(Limits limits) : limits_(limits) {}

TrajectoryAssembler::Progress TrajectoryAssembler::progress(std::uint64_t id, const Upload& upload) const {
  Progress p;
  p.trajectory_id = id;
  p.chunks_received = upload.chunks_received;
  p.chunk_count = upload.chunk_count;
  if (upload.rejected) {
    p.state = foresight_msg_UPLOAD_REJECTED;
    p.code = upload.code;
    p.reason = upload.reason;
  } else {
    p.state = upload.chunks_received == upload.chunk_count ? foresight_msg_UPLOAD_COMMITTED
                                                            : foresight_msg_UPLOAD_ASSEMBLING;
    p.code = foresight_msg_REASON_NONE;
  }
  return p;
}

TrajectoryAssembler::Progress TrajectoryAssembler::reject(std::uint64_t id, Upload& upload, msg::ReasonCode code,
                                                          std::string reason) {
  upload.rejected = true;
  upload.code = code;
  upload.reason = "trajectory " + std::to_string(id) + ": " + std::move(reason);
  // Keep only the verdict: the data of a rejected upload is never used.
  upload.chunk_values = {};
  upload.sample_covered = {};
  return progress(id, upload);
}

TrajectoryAssembler::Progress TrajectoryAssembler::add(const msg::TrajectoryChunk& chunk) {
  const std::uint64_t id = chunk.trajectory_id;
  const std::string where = "chunk " + std::to_string(chunk.chunk_index);
  auto it = uploads_.find(id);
  if (it == uploads_.end()) {
    Upload fresh;
    fresh.chunk_count = chunk.chunk_count;
    if (uploads_.size() >= limits_.max_pending) {
      Progress p = reject(id, fresh, foresight_msg_REASON_BUSY,
                          std::to_string(uploads_.size()) + " uploads are already pending (limit " +
                              std::to_string(limits_.max_pending) + ")");
      return p;  // not remembered: the limit is about memory
    }
    const auto of_session = static_cast<std::size_t>(std::count_if(uploads_.begin(), uploads_.end(), [&](const auto& e) {
      return !e.second.rejected && e.second.session_id == chunk.session_id;
    }));
    if (of_session >= limits_.max_pending_per_session) {
      Progress p = reject(id, fresh, foresight_msg_REASON_BUSY,
                          std::to_string(of_session) + " uploads of this session are already pending (limit " +
                              std::to_string(limits_.max_pending_per_session) + " per session)");
      return p;
    }
    it = uploads_.emplace(id, std::move(fresh)).first;
    Upload& u = it->second;
    u.session_id = chunk.session_id;
    u.joint_count = chunk.joint_count;
    u.sample_count = chunk.sample_count;
    u.hash = get_hash(chunk.content_hash);
    if (chunk.chunk_count == 0 || chunk.chunk_count > msg::kMaxChunks) {
      return reject(id, u, foresight_msg_REASON_BAD_ARGUMENT,
                    where + ": chunk_count " + std::to_string(chunk.chunk_count) + " is not in 1.." +
                        std::to_string(msg::kMaxChunks));
    }
    if (chunk.joint_count == 0 || chunk.joint_count > limits_.max_joints) {
      return reject(id, u, foresight_msg_REASON_JOINT_COUNT,
                    where + ": joint_count " + std::to_string(chunk.joint_count) + " is not in 1.." +
                        std::to_string(limits_.max_joints));
    }
    if (chunk.sample_count == 0 || chunk.sample_count > limits_.max_samples) {
      return reject(id, u, foresight_msg_REASON_BAD_ARGUMENT,
                    where + ": sample_count " + std::to_string(chunk.sample_count) + " is not in 1.." +
                        std::to_string(limits_.max_samples));
    }
    if (chunk.chunk_count > chunk.sample_count) {
      return reject(id, u, foresight_msg_REASON_BAD_ARGUMENT,
                    where + ": " + std::to_string(chunk.chunk_count) + " chunks for " +
                        std::to_string(chunk.sample_count) + " samples");
    }
    u.chunk_values.resize(u.chunk_count);  // empty vectors: the values come with their chunks
    u.sample_covered.assign(u.sample_count, false);
    u.chunk_received.assign(u.chunk_count, false);
    u.chunk_first.assign(u.chunk_count, 0);
    u.chunk_samples.assign(u.chunk_count, 0);
  }
  Upload& u = it->second;
  if (u.rejected) return progress(id, u);
  u.last_chunk = std::chrono::steady_clock::now();

  // Every chunk must describe the same whole as the first one.
  auto mismatch = [&](const char* field, std::uint64_t got, std::uint64_t expected) {
    return reject(id, u, foresight_msg_REASON_BAD_ARGUMENT,
                  where + ": " + field + " " + std::to_string(got) + " differs from " + std::to_string(expected) +
                      " in the upload's first chunk");
  };
  if (chunk.chunk_count != u.chunk_count) return mismatch("chunk_count", chunk.chunk_count, u.chunk_count);
  if (chunk.joint_count != u.joint_count) return mismatch("joint_count", chunk.joint_count, u.joint_count);
  if (chunk.sample_count != u.sample_count) return mismatch("sample_count", chunk.sample_count, u.sample_count);
  if (chunk.session_id != u.session_id) return mismatch("session_id", chunk.session_id, u.session_id);
  if (get_hash(chunk.content_hash) != u.hash) {
    return reject(id, u, foresight_msg_REASON_HASH_MISMATCH,
                  where + ": content_hash " + to_hex(get_hash(chunk.content_hash)) +
                      " differs from the upload's first chunk " + to_hex(u.hash));
  }
  if (chunk.chunk_index >= u.chunk_count) {
    return reject(id, u, foresight_msg_REASON_BAD_ARGUMENT,
                  where + ": chunk_index is not below chunk_count " + std::to_string(u.chunk_count));
  }
  const std::uint32_t row = u.joint_count + 1;
  if (chunk.samples._length == 0 || chunk.samples._length % row != 0) {
    return reject(id, u, foresight_msg_REASON_BAD_ARGUMENT,
                  where + ": " + std::to_string(chunk.samples._length) +
                      " values are not a positive multiple of joint_count + 1 = " + std::to_string(row));
  }
  const std::uint32_t n = chunk.samples._length / row;
  if (chunk.first_sample >= u.sample_count || n > u.sample_count - chunk.first_sample) {
    return reject(id, u, foresight_msg_REASON_BAD_ARGUMENT,
                  where + ": samples " + std::to_string(chunk.first_sample + 1) + ".." +
                      std::to_string(static_cast<std::uint64_t>(chunk.first_sample) + n) + " exceed sample_count " +
                      std::to_string(u.sample_count));
  }
  const std::span<const double> values = view(chunk.samples);
  std::vector<double>& kept = u.chunk_values[chunk.chunk_index];
  if (u.chunk_received[chunk.chunk_index]) {
    const bool same = u.chunk_first[chunk.chunk_index] == chunk.first_sample &&
                      u.chunk_samples[chunk.chunk_index] == n && kept.size() == values.size() &&
                      std::memcmp(kept.data(), values.data(), values.size_bytes()) == 0;
    if (same) return progress(id, u);  // harmless duplicate
    return reject(id, u, foresight_msg_REASON_BAD_ARGUMENT, where + ": received twice with different content");
  }
  for (std::uint32_t s = chunk.first_sample; s < chunk.first_sample + n; ++s) {
    if (u.sample_covered[s]) {
      return reject(id, u, foresight_msg_REASON_BAD_ARGUMENT,
                    where + ": sample " + std::to_string(s + 1) + " was already sent in another chunk");
    }
  }
  std::fill(u.sample_covered.begin() + chunk.first_sample, u.sample_covered.begin() + chunk.first_sample + n, true);
  kept.assign(values.begin(), values.end());
  u.chunk_received[chunk.chunk_index] = true;
  u.chunk_first[chunk.chunk_index] = chunk.first_sample;
  u.chunk_samples[chunk.chunk_index] = n;
  ++u.chunks_received;
  if (u.chunks_received == u.chunk_count) {
    const auto gap = std::find(u.sample_covered.begin(), u.sample_covered.end(), false);
    if (gap != u.sample_covered.end()) {
      return reject(id, u, foresight_msg_REASON_INCOMPLETE_UPLOAD,
                    "all " + std::to_string(u.chunk_count) + " chunks arrived but sample " +
                        std::to_string(gap - u.sample_covered.begin() + 1) + " is in none of them");
    }
  }
  return progress(id, u);
}

std::optional<AssembledTrajectory> TrajectoryAssembler::take(std::uint64_t trajectory_id) {
  const auto it = uploads_.find(trajectory_id);
  if (it == uploads_.end() || it->second.rejected || it->second.chunks_received != it->second.chunk_count) {
    return std::nullopt;
  }
  const Upload& u = it->second;
  AssembledTrajectory out;
  out.trajectory_id = trajectory_id;
  out.session_id = u.session_id;
  out.declared_hash = u.hash;
  const std::uint32_t row = u.joint_count + 1;
  out.trajectory.time_s.resize(u.sample_count);
  out.trajectory.positions_rad.resize(u.sample_count, u.joint_count);
  for (std::uint32_t c = 0; c < u.chunk_count; ++c) {
    const std::vector<double>& v = u.chunk_values[c];
    for (std::uint32_t k = 0; k < u.chunk_samples[c]; ++k) {
      const std::uint32_t s = u.chunk_first[c] + k;
      out.trajectory.time_s[s] = v[static_cast<std::size_t>(k) * row];
      for (std::uint32_t j = 0; j < u.joint_count; ++j)
        out.trajectory.positions_rad(s, j) = v[static_cast<std::size_t>(k) * row + 1 + j];
    }
  }
  uploads_.erase(it);
  return out;
}

void TrajectoryAssembler::discard(std::uint64_t trajectory_id) { uploads_.erase(trajectory_id); }

std::vector<TrajectoryAssembler::Progress> TrajectoryAssembler::expire(std::chrono::steady_clock::time_point now,
                                                                        std::chrono::nanoseconds idle) {
  std::vector<Progress> out;
  for (auto& [id, u] : uploads_) {
    if (u.rejected || u.chunks_received == u.chunk_count || now - u.last_chunk <= idle) continue;
    char secs[32];
    std::snprintf(secs, sizeof secs, "%.0f", std::chrono::duration<double>(idle).count());
    out.push_back(reject(id, u, foresight_msg_REASON_INCOMPLETE_UPLOAD,
                         std::string("no chunk for ") + secs + " s: " + std::to_string(u.chunks_received) + " of " +
                             std::to_string(u.chunk_count) + " chunks arrived"));
  }
  return out;
}

std::size_t TrajectoryAssembler::values_held() const noexcept {
  std::size_t n = 0;
  for (const auto& [id, u] : uploads_)
    for (const auto& v : u.chunk_values) n += v.size();
  return n;
}

bool UploadVerdict::ok() const noexcept { return code == foresight_msg_REASON_NONE; }

UploadVerdict verify(const AssembledTrajectory& assembled, const TrajectoryLimits& limits) {
  UploadVerdict verdict;
  verdict.code = foresight_msg_REASON_NONE;
  verdict.computed_hash = trajectory_hash(assembled.trajectory);
  const std::string name = "trajectory " + std::to_string(assembled.trajectory_id);
  if (verdict.computed_hash != assembled.declared_hash) {
    verdict.code = foresight_msg_REASON_HASH_MISMATCH;
    verdict.reason = name + ": content hash " + to_hex(verdict.computed_hash) + " differs from the declared " +
                     to_hex(assembled.declared_hash);
    return verdict;
  }
  verdict.violations = validate(assembled.trajectory, limits);
  if (!verdict.violations.empty()) {
    verdict.code = foresight_msg_REASON_VALIDATION_FAILED;
    std::ostringstream text;
    text << name << ": " << verdict.violations.size() << " violation(s): ";
    const std::size_t shown = std::min<std::size_t>(verdict.violations.size(), 3);
    for (std::size_t i = 0; i < shown; ++i) text << (i > 0 ? "; " : "") << verdict.violations[i].message;
    if (shown < verdict.violations.size()) text << "; ...";
    verdict.reason = text.str();
  }
  return verdict;
}

}  // namespace foresight::protocol
