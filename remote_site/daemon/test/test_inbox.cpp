// The supervisor's own bound on what the link hands it (issue 28: "the queue
// is bounded"): past its limit a command is dropped and counted, an ABORT
// still passes, upload and link events always pass.
#include <gtest/gtest.h>

#include <thread>

#include "foresight/daemon/inbox.hpp"

using foresight::daemon::Inbox;
namespace protocol = foresight::protocol;
namespace rl = foresight::remote_link;

namespace {
rl::CommandEvent command(protocol::CommandKind kind, std::uint64_t id) {
  rl::CommandEvent e;
  e.command.kind = kind;
  e.command.command_id = id;
  return e;
}
}  // namespace

TEST(Inbox, PastItsLimitCommandsAreDroppedButAbortsAndEventsPass) {
  Inbox inbox(4);
  for (std::uint64_t i = 1; i <= 6; ++i) EXPECT_EQ(inbox.push(command(protocol::CommandKind::Request, i)), i <= 4) << i;
  EXPECT_TRUE(inbox.push(command(protocol::CommandKind::Abort, 7)));  // a full inbox still takes an ABORT
  EXPECT_TRUE(inbox.push(rl::UploadEvent{}));
  EXPECT_TRUE(inbox.push(rl::LinkEvent{}));
  EXPECT_EQ(inbox.take_dropped(), 2u);
  EXPECT_EQ(inbox.take_dropped(), 0u);  // counted once

  const auto batch = inbox.take_all();
  ASSERT_EQ(batch.size(), 7u);  // 4 commands, the ABORT, the two events, in order
  std::vector<std::uint64_t> ids;
  for (const auto& item : batch)
    if (const auto* c = std::get_if<rl::CommandEvent>(&item)) ids.push_back(c->command.command_id);
  EXPECT_EQ(ids, (std::vector<std::uint64_t>{1, 2, 3, 4, 7}));
  EXPECT_TRUE(std::holds_alternative<rl::UploadEvent>(batch[5]));
  EXPECT_TRUE(std::holds_alternative<rl::LinkEvent>(batch[6]));

  // Taken: room again.
  EXPECT_TRUE(inbox.take_all().empty());
  for (std::uint64_t i = 10; i < 14; ++i) EXPECT_TRUE(inbox.push(command(protocol::CommandKind::GotoJoint, i)));
  EXPECT_FALSE(inbox.push(command(protocol::CommandKind::GotoJoint, 14)));
}

TEST(Inbox, WaitWakesOnAPushFromAnotherThread) {
  Inbox inbox;
  std::thread t([&] { inbox.push(command(protocol::CommandKind::Abort, 1)); });
  // Bounded: at most 10 s; the push wakes the wait (or was there before it).
  std::deque<Inbox::Item> got;
  for (int i = 0; i < 1000 && got.empty(); ++i) {
    inbox.wait(std::chrono::milliseconds(10));
    got = inbox.take_all();
  }
  t.join();
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(std::get<rl::CommandEvent>(got.front()).command.command_id, 1u);
}
