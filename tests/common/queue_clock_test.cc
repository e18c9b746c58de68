#include <cmath>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "common/bounded_queue.h"
#include "common/clock.h"
#include "common/file_util.h"
#include "common/status.h"

namespace holo {
namespace {

TEST(BoundedQueueTest, FifoAcrossThreadsWithBackpressure) {
  BoundedQueue<int> q(4);
  std::thread producer([&] {
    for (int i = 0; i < 1000; ++i) ASSERT_TRUE(q.Push(i));
    q.Close();
  });
  std::vector<int> got;
  while (auto v = q.Pop()) {
    EXPECT_LE(q.size(), 4u);
    got.push_back(*v);
  }
  producer.join();
  ASSERT_EQ(got.size(), 1000u);
  for (int i = 0; i < 1000; ++i) EXPECT_EQ(got[i], i);
}

TEST(BoundedQueueTest, NonBlockingPushesDropAsDocumented) {
  BoundedQueue<int> q(2);
  EXPECT_TRUE(q.TryPush(1));
  EXPECT_TRUE(q.TryPush(2));
  EXPECT_FALSE(q.TryPush(3)) << "full: dropped";
  EXPECT_EQ(q.PushDropOldest(4), 1u) << "full: oldest dropped";
  EXPECT_EQ(*q.Pop(), 2);
  EXPECT_EQ(*q.Pop(), 4);
  EXPECT_FALSE(q.TryPop().has_value());
  q.Close();
  EXPECT_FALSE(q.Push(5));
  EXPECT_FALSE(q.Pop().has_value());
}

TEST(BoundedQueueTest, CloseWakesBlockedConsumer) {
  BoundedQueue<int> q(1);
  std::thread consumer([&] { EXPECT_FALSE(q.Pop().has_value()); });
  q.Close();
  consumer.join();
}

TEST(ClockTest, SimulatedClockMovesOnlyWhenTold) {
  SimulatedClock clock(1000);
  EXPECT_EQ(clock.NowUs(), 1000);
  clock.AdvanceUs(20000);
  EXPECT_EQ(clock.NowUs(), 21000);
  clock.SleepUntilUs(50000);
  EXPECT_EQ(clock.NowUs(), 50000);
  clock.SleepUntilUs(10);  // in the past: no change
  EXPECT_EQ(clock.NowUs(), 50000);
}

TEST(ClockTest, RealClockIsMonotonic) {
  RealClock& clock = RealClock::Instance();
  const int64_t a = clock.NowUs();
  clock.SleepUntilUs(a + 2000);
  EXPECT_GE(clock.NowUs(), a + 2000);
}

StatusOr<int> Half(int x) {
  if (x % 2) return InvalidArgument("odd: " + std::to_string(x));
  return x / 2;
}

Status Quarter(int x, int* out) {
  HOLO_ASSIGN_OR_RETURN(int h, Half(x));
  HOLO_ASSIGN_OR_RETURN(*out, Half(h));
  return OkStatus();
}

TEST(StatusTest, PropagationMacros) {
  int out = 0;
  EXPECT_TRUE(Quarter(8, &out).ok());
  EXPECT_EQ(out, 2);
  const Status s = Quarter(6, &out);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(s.ToString(), "InvalidArgument: odd: 3");
  EXPECT_EQ(s.WithContext("file.yaml").message(), "file.yaml: odd: 3");
}

TEST(StatusTest, FormatNumberAsMessagesShowIt) {
  EXPECT_EQ(FormatNumber(640), "640");
  EXPECT_EQ(FormatNumber(-1), "-1");
  EXPECT_EQ(FormatNumber(0.25), "0.25");
  EXPECT_EQ(FormatNumber(1e30), "1e+30");
  EXPECT_EQ(FormatNumber(std::nan("")), "nan");
}

TEST(FileUtilTest, PathNextTo) {
  EXPECT_EQ(PathNextTo("sites/call.yaml", "ca.pem"), "sites/ca.pem");
  EXPECT_EQ(PathNextTo("/etc/holo/site.yaml", "tls/site.key"), "/etc/holo/tls/site.key");
  EXPECT_EQ(PathNextTo("sites/call.yaml", "/abs/ca.pem"), "/abs/ca.pem");
  EXPECT_EQ(PathNextTo("call.yaml", "ca.pem"), "ca.pem");
  EXPECT_EQ(PathNextTo("sites/call.yaml", ""), "");
}

TEST(StatusDeathTest, ValueOfErrorAborts) {
  EXPECT_DEATH({ (void)Half(3).value(); }, "odd: 3");
}

}  // namespace
}  // namespace holo
