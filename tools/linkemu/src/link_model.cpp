#include "foresight/linkemu/link_model.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace foresight::linkemu {

void validate(const LinkParams& p) {
  auto fail = [](const std::string& what) { throw std::invalid_argument(what); };
  if (p.delay_ns < 0) fail("delay must be >= 0");
  if (p.jitter_ns < 0) fail("jitter must be >= 0");
  if (!(p.loss >= 0.0 && p.loss <= 1.0)) fail("loss must be a probability in [0, 1]");
  if (!(p.reorder >= 0.0 && p.reorder <= 1.0)) fail("reorder must be a probability in [0, 1]");
  if (p.reorder_gap_ns < 0) fail("reorder gap must be >= 0");
  if (!(p.rate_bit_s >= 0.0) || !std::isfinite(p.rate_bit_s)) fail("rate must be >= 0 (0 = unlimited)");
  if (p.burst_bytes <= 0) fail("burst must be > 0 bytes");
  if (p.queue_bytes <= 0) fail("queue limit must be > 0 bytes");
}

DirectionModel::DirectionModel(const LinkParams& params, std::uint64_t seed) : params_(params), rng_(seed) {
  validate(params_);
}

Decision DirectionModel::admit(std::int64_t now_ns, std::int64_t bytes) noexcept {
  Decision d;
  // Draw both random numbers for every packet so the loss pattern for a seed
  // does not depend on the other settings.
  const double u_loss = unit_(rng_);
  const double u_reorder = unit_(rng_);
  const double u_jitter = unit_(rng_);
  if (u_loss < params_.loss) {
    d.verdict = Verdict::kDropLoss;
    return d;
  }

  // Token bucket as a virtual finish time: the bucket is full when the
  // virtual time lags `now` by burst/rate; each packet advances it by its
  // transmission time. The packet leaves the shaper at max(now, finish).
  double depart_ns = static_cast<double>(now_ns);
  if (params_.rate_bit_s > 0.0) {
    const double ns_per_byte = 8e9 / params_.rate_bit_s;
    const double earliest = static_cast<double>(now_ns) - static_cast<double>(params_.burst_bytes) * ns_per_byte;
    const double finish = std::max(virtual_finish_ns_, earliest) + static_cast<double>(bytes) * ns_per_byte;
    const double wait_ns = finish - static_cast<double>(now_ns);
    // Bytes waiting ahead of (and including) this one, in the FIFO.
    if (wait_ns > 0.0 && wait_ns / ns_per_byte > static_cast<double>(params_.queue_bytes)) {
      d.verdict = Verdict::kDropQueue;
      return d;
    }
    virtual_finish_ns_ = finish;
    depart_ns = std::max(depart_ns, finish);
  }

  std::int64_t deliver = static_cast<std::int64_t>(std::llround(depart_ns)) + params_.delay_ns;
  if (params_.jitter_ns > 0) {
    const double offset = (2.0 * u_jitter - 1.0) * static_cast<double>(params_.jitter_ns);
    deliver = std::max(static_cast<std::int64_t>(std::llround(depart_ns)),
                       deliver + static_cast<std::int64_t>(std::llround(offset)));
  }
  if (params_.reorder > 0.0 && u_reorder < params_.reorder) {
    // Held back; it does not move the in-order horizon, so later packets may
    // pass it.
    d.reordered = true;
    d.deliver_ns = std::max(deliver, last_in_order_ns_) + params_.reorder_gap_ns;
    return d;
  }
  deliver = std::max(deliver, last_in_order_ns_);
  last_in_order_ns_ = deliver;
  d.deliver_ns = deliver;
  return d;
}

}  // namespace foresight::linkemu
