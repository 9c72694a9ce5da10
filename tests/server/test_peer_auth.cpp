#include <gtest/gtest.h>
#include <sys/socket.h>
#include <unistd.h>

#include <stdexcept>

#include "daemon/outputs/server/peer_auth.hpp"

namespace scp::daemon::server {
namespace {

TEST(PeerAuth, Rules) {
  AuthPolicy no_group{1000, std::nullopt, ""};
  AuthPolicy with_group{1000, 555, "scp"};
  const PeerIdentity root{1, 0, 0, {}};
  const PeerIdentity daemon_user{2, 1000, 1000, {}};
  const PeerIdentity stranger{3, 2000, 2000, {4, 24}};
  const PeerIdentity primary{4, 2001, 555, {}};
  const PeerIdentity supplementary{5, 2002, 2002, {4, 555, 27}};
  for (const AuthPolicy& p : {no_group, with_group}) {
    EXPECT_TRUE(is_privileged(root, p));
    EXPECT_TRUE(is_privileged(daemon_user, p));
    EXPECT_FALSE(is_privileged(stranger, p));
  }
  EXPECT_FALSE(is_privileged(primary, no_group));
  EXPECT_FALSE(is_privileged(supplementary, no_group));
  EXPECT_TRUE(is_privileged(primary, with_group));
  EXPECT_TRUE(is_privileged(supplementary, with_group));
}

TEST(PeerAuth, MessagesNameTheRemedy) {
  const std::string with = permission_denied_message("reset", AuthPolicy{0, 555, "scp"});
  EXPECT_NE(with.find("permission denied: 'reset'"), std::string::npos) << with;
  EXPECT_NE(with.find("add the user to group scp"), std::string::npos) << with;
  const std::string without = permission_denied_message("clear-fault", AuthPolicy{});
  EXPECT_NE(without.find("permission denied: 'clear-fault'"), std::string::npos) << without;
  EXPECT_NE(without.find("socket.group"), std::string::npos) << without;
}

TEST(PeerAuth, ProcStatusGroups) {
  const std::string text =
      "Name:\tbash\nUid:\t1000\t1000\t1000\t1000\nGroups:\t4 24 27 1000 \nNSpid:\t1\n";
  EXPECT_EQ(parse_proc_status_groups(text), (std::vector<gid_t>{4, 24, 27, 1000}));
  EXPECT_TRUE(parse_proc_status_groups("Groups:\t\nX: 1\n").empty());
  EXPECT_TRUE(parse_proc_status_groups("Name: x\n").empty());
}

TEST(PeerAuth, PeerIdentityOfASocketPairIsOurselves) {
  int fds[2];
  ASSERT_EQ(::socketpair(AF_UNIX, SOCK_STREAM, 0, fds), 0);
  const auto peer = peer_identity(fds[0]);
  ASSERT_TRUE(peer.has_value());
  EXPECT_EQ(peer->uid, ::geteuid());
  EXPECT_EQ(peer->gid, ::getegid());
  EXPECT_EQ(peer->pid, ::getpid());
  std::vector<gid_t> ours(static_cast<std::size_t>(::getgroups(0, nullptr)));
  ::getgroups(static_cast<int>(ours.size()), ours.data());
  for (gid_t g : ours)
    EXPECT_NE(std::find(peer->groups.begin(), peer->groups.end(), g), peer->groups.end()) << g;
  ::close(fds[0]);
  ::close(fds[1]);
}

TEST(PeerAuth, ResolveGroup) {
  EXPECT_EQ(resolve_group("root"), 0U);
  EXPECT_EQ(resolve_group("4242"), 4242U);
  try {
    resolve_group("no-such-group-scp-test");
    FAIL() << "expected an exception";
  } catch (const std::runtime_error& error) {
    EXPECT_NE(std::string(error.what()).find("groupadd no-such-group-scp-test"), std::string::npos);
  }
}

}  // namespace
}  // namespace scp::daemon::server
