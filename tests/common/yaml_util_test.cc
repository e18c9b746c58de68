// The YAML helpers shared by the config parsers (rig, site server, call):
// every error names the key with its path and says what is wrong.
#include <string>

#include <gtest/gtest.h>

#include "common/yaml_util.h"

namespace holo {
namespace {

TEST(YamlUtil, KeyErrorIsKeyColonMessage) {
  const Status s = KeyError("room.yaw_deg", "must be a number");
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(s.message(), "room.yaw_deg: must be a number");
}

TEST(YamlUtil, LoadYamlNamesTheSourceOnSyntaxErrors) {
  auto bad = LoadYaml("key: [unclosed\n", "site.yaml");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(bad.status().message().rfind("site.yaml: not valid YAML: ", 0), 0u) << bad.status().message();
  auto empty = LoadYaml("", "site.yaml");
  ASSERT_TRUE(empty.ok());
  EXPECT_TRUE(empty->IsNull());
  auto good = LoadYaml("a: 1\n", "site.yaml");
  ASSERT_TRUE(good.ok());
  EXPECT_EQ((*good)["a"].as<int>(), 1);
}

TEST(YamlUtil, CheckKeysListsTheKnownKeys) {
  const YAML::Node m = YAML::Load("{enabled: true, crt: x}");
  EXPECT_TRUE(CheckYamlKeys(m, {"enabled", "crt"}, "tls.").ok());
  const Status s = CheckYamlKeys(m, {"enabled", "cert", "key"}, "tls.");
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message(), "tls.crt: unknown key (known: cert, enabled, key)");
  EXPECT_EQ(CheckYamlKeys(YAML::Load("{b: 1}"), {"a"}, "").message(), "b: unknown key (known: a)");
  // A list or map as a key is an error, not an exception.
  EXPECT_EQ(CheckYamlKeys(YAML::Load("{[a]: 1}"), {"a"}, "tls.").message(),
            "tls: keys must be names, not lists or maps");
  EXPECT_EQ(CheckYamlKeys(YAML::Load("{{a: 1}: 2}"), {"a"}, "").message(),
            "(top level): keys must be names, not lists or maps");
}

TEST(YamlUtil, GetStringAndBool) {
  const YAML::Node m = YAML::Load("{name: alice, list: [1, 2], on: true, maybe: perhaps}");
  std::string s = "unchanged";
  EXPECT_TRUE(GetYamlString(m, "absent", "site.", &s).ok());
  EXPECT_EQ(s, "unchanged");
  EXPECT_TRUE(GetYamlString(m, "name", "site.", &s).ok());
  EXPECT_EQ(s, "alice");
  EXPECT_EQ(GetYamlString(m, "list", "site.", &s).message(), "site.list: must be a string");
  bool b = false;
  EXPECT_TRUE(GetYamlBool(m, "absent", "", &b).ok());
  EXPECT_FALSE(b);
  EXPECT_TRUE(GetYamlBool(m, "on", "", &b).ok());
  EXPECT_TRUE(b);
  EXPECT_EQ(GetYamlBool(m, "maybe", "tls.", &b).message(), "tls.maybe: must be true or false");
  EXPECT_EQ(GetYamlBool(m, "list", "", &b).message(), "list: must be true or false");
}

}  // namespace
}  // namespace holo
