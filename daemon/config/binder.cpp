#include "daemon/config/binder.hpp"

#include <yaml-cpp/yaml.h>

#include <charconv>
#include <cmath>
#include <set>
#include <sstream>

namespace scp::config {

namespace {

std::string format_number(double value) {
  std::ostringstream out;
  out.precision(12);
  out << value;
  return out.str();
}

std::string range_text(double min, double max) {
  return "[" + format_number(min) + ", " + format_number(max) + "]";
}

// yaml-cpp marks are 0-based; users count lines from 1.
int line_of_node(const YAML::Node& node) {
  if (!node.IsDefined() || node.IsNull()) return 0;
  const YAML::Mark mark = node.Mark();
  return mark.line >= 0 ? mark.line + 1 : 0;
}

// yaml-cpp keeps both entries of a key written twice and lookups find the first, so a second
// `loop:` section would be ignored without a word. Every mapping is checked, at any depth.
void reject_duplicate_keys(const YAML::Node& node, const std::string& prefix,
                           const std::string& file) {
  if (node.IsSequence()) {
    for (std::size_t i = 0; i < node.size(); ++i) {
      reject_duplicate_keys(node[i],
                            prefix.substr(0, prefix.size() - (prefix.empty() ? 0 : 1)) + "[" +
                                std::to_string(i) + "].",
                            file);
    }
    return;
  }
  if (!node.IsMap()) return;
  std::vector<std::pair<std::string, int>> seen;
  for (auto it = node.begin(); it != node.end(); ++it) {
    const std::string key = it->first.IsScalar() ? it->first.Scalar() : std::string("?");
    const int line = line_of_node(it->first);
    for (const auto& [name, first_line] : seen) {
      if (name != key) continue;
      std::ostringstream out;
      out << file << ":" << line << ": duplicate key '" << prefix << key << "' (first at line "
          << first_line << "); YAML would silently keep only one of them: merge the two";
      throw ConfigError(out.str());
    }
    seen.emplace_back(key, line);
    reject_duplicate_keys(it->second, prefix + key + ".", file);
  }
}

}  // namespace

struct Binder::Shared {
  std::string file;
  bool documenting = false;
  YAML::Node root;
  std::vector<KeyDoc> docs;
  std::set<std::string> declared;  // full paths of declared leaves, sections and lists
  std::set<std::string> lists;     // full paths declared as lists
};

struct Binder::Impl {
  std::shared_ptr<Shared> shared;
  YAML::Node node;         // the mapping this binder reads (undefined or null: all defaults)
  std::string prefix;      // "estimator." for a section, "" at the root
  std::string doc_prefix;  // like prefix, but list items are written "key[]." for the reference
  bool record_docs = true;
  bool template_item = false;

  std::string path(std::string_view key) const { return prefix + std::string(key); }

  YAML::Node child(std::string_view key) const {
    if (!node.IsDefined() || !node.IsMap()) return YAML::Node(YAML::NodeType::Undefined);
    for (auto it = node.begin(); it != node.end(); ++it) {
      if (it->first.IsScalar() && it->first.Scalar() == key) return it->second;
    }
    return YAML::Node(YAML::NodeType::Undefined);
  }

  void declare(std::string_view key, std::string type, std::string deflt, std::string range,
               std::string_view doc) {
    shared->declared.insert(path(key));
    if (!record_docs) return;
    shared->docs.push_back(KeyDoc{doc_prefix + std::string(key), std::move(type), std::move(deflt),
                                  std::move(range), std::string(doc)});
  }

  [[noreturn]] void fail_at(const YAML::Node& at, std::string_view key,
                            const std::string& message) const {
    std::ostringstream out;
    out << shared->file;
    if (const int line = line_of_node(at); line > 0) out << ":" << line;
    out << ": " << path(key) << ": " << message;
    throw ConfigError(out.str());
  }

  // Reads a finite number, or fails naming the key.
  double read_number(std::string_view key, const YAML::Node& value,
                     const std::string& expect) const {
    if (!value.IsScalar()) fail_at(value, key, "expected a number " + expect);
    const std::string& text = value.Scalar();
    double parsed = 0.0;
    const char* begin = text.data();
    const char* end = text.data() + text.size();
    if (!text.empty() && *begin == '+') ++begin;
    const auto result = std::from_chars(begin, end, parsed);
    if (result.ec != std::errc() || result.ptr != end || !std::isfinite(parsed)) {
      fail_at(value, key, "'" + text + "' is not a finite number; expected a number " + expect);
    }
    return parsed;
  }
};

Binder::Binder(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Binder::~Binder() = default;
Binder::Binder(Binder&&) noexcept = default;
Binder& Binder::operator=(Binder&&) noexcept = default;

Binder Binder::reading(const YAML::Node& root, std::string file) {
  auto shared = std::make_shared<Shared>();
  shared->file = std::move(file);
  shared->root = root;
  auto impl = std::make_unique<Impl>();
  impl->shared = shared;
  impl->node = root;
  if (root.IsDefined() && !root.IsNull() && !root.IsMap()) {
    throw ConfigError(shared->file + ":" + std::to_string(line_of_node(root)) +
                      ": the top level must be a mapping of sections (key: value), "
                      "see config/sim.yaml");
  }
  reject_duplicate_keys(root, "", shared->file);
  return Binder(std::move(impl));
}

Binder Binder::documenting() {
  auto impl = std::make_unique<Impl>();
  impl->shared = std::make_shared<Shared>();
  impl->shared->documenting = true;
  impl->shared->file = "(defaults)";
  impl->node = YAML::Node(YAML::NodeType::Undefined);
  return Binder(std::move(impl));
}

void Binder::number(std::string_view key, double& out, double def, double min, double max,
                    std::string_view doc) {
  impl_->declare(key, "number", format_number(def), range_text(min, max), doc);
  out = def;
  const YAML::Node value = impl_->child(key);
  if (!value.IsDefined() || value.IsNull()) return;
  const std::string expect = "in " + range_text(min, max) + " (" + std::string(doc) + ")";
  const double parsed = impl_->read_number(key, value, expect);
  if (parsed < min || parsed > max) {
    impl_->fail_at(value, key, format_number(parsed) + " is out of range; allowed " + expect);
  }
  out = parsed;
}

void Binder::number_or_word(std::string_view key, std::optional<double>& out, std::string_view word,
                            std::string_view def, double min, double max, std::string_view doc) {
  const std::string w(word);
  impl_->declare(key, "number or `" + w + "`", std::string(def), range_text(min, max), doc);
  const std::string expect =
      "in " + range_text(min, max) + " or `" + w + "` (" + std::string(doc) + ")";
  const auto parse = [&](const YAML::Node& value) -> std::optional<double> {
    if (value.IsScalar() && value.Scalar() == word) return std::nullopt;
    const double parsed = impl_->read_number(key, value, expect);
    if (parsed < min || parsed > max) {
      impl_->fail_at(value, key, format_number(parsed) + " is out of range; allowed " + expect);
    }
    return parsed;
  };
  out = parse(YAML::Node(std::string(def)));
  const YAML::Node value = impl_->child(key);
  if (!value.IsDefined() || value.IsNull()) return;
  out = parse(value);
}

void Binder::integer(std::string_view key, std::int64_t& out, std::int64_t def, std::int64_t min,
                     std::int64_t max, std::string_view doc) {
  const std::string range = "[" + std::to_string(min) + ", " + std::to_string(max) + "]";
  impl_->declare(key, "integer", std::to_string(def), range, doc);
  out = def;
  const YAML::Node value = impl_->child(key);
  if (!value.IsDefined() || value.IsNull()) return;
  const std::string expect = "in " + range + " (" + std::string(doc) + ")";
  if (!value.IsScalar()) impl_->fail_at(value, key, "expected a whole number " + expect);
  const std::string& text = value.Scalar();
  std::int64_t parsed = 0;
  const char* begin = text.data();
  const char* end = text.data() + text.size();
  int base = 10;
  if (text.size() > 2 && text[0] == '0' && (text[1] == 'x' || text[1] == 'X')) {
    begin += 2;
    base = 16;
  }
  const auto result = std::from_chars(begin, end, parsed, base);
  if (result.ec != std::errc() || result.ptr != end) {
    impl_->fail_at(value, key, "'" + text + "' is not a whole number; expected " + expect);
  }
  if (parsed < min || parsed > max) {
    impl_->fail_at(value, key, text + " is out of range; allowed " + expect);
  }
  out = parsed;
}

void Binder::boolean(std::string_view key, bool& out, bool def, std::string_view doc) {
  impl_->declare(key, "bool", def ? "true" : "false", "true|false", doc);
  out = def;
  const YAML::Node value = impl_->child(key);
  if (!value.IsDefined() || value.IsNull()) return;
  const std::string text = value.IsScalar() ? value.Scalar() : std::string();
  if (text == "true" || text == "True" || text == "yes" || text == "on") {
    out = true;
  } else if (text == "false" || text == "False" || text == "no" || text == "off") {
    out = false;
  } else {
    impl_->fail_at(
        value, key,
        "'" + text + "' is not a boolean; write true or false (" + std::string(doc) + ")");
  }
}

void Binder::text(std::string_view key, std::string& out, std::string_view def,
                  std::string_view doc) {
  impl_->declare(key, "string", "\"" + std::string(def) + "\"", "", doc);
  out = std::string(def);
  const YAML::Node value = impl_->child(key);
  if (!value.IsDefined() || value.IsNull()) return;
  if (!value.IsScalar()) impl_->fail_at(value, key, "expected a string (" + std::string(doc) + ")");
  out = value.Scalar();
}

void Binder::choice(std::string_view key, std::string& out, std::string_view def,
                    std::span<const std::string_view> allowed, std::string_view doc) {
  std::string options;
  for (const auto option : allowed) {
    if (!options.empty()) options += "|";
    options += option;
  }
  impl_->declare(key, "one of " + options, std::string(def), options, doc);
  out = std::string(def);
  const YAML::Node value = impl_->child(key);
  if (!value.IsDefined() || value.IsNull()) return;
  const std::string text = value.IsScalar() ? value.Scalar() : std::string("(not a scalar)");
  for (const auto option : allowed) {
    if (text == option) {
      out = text;
      return;
    }
  }
  impl_->fail_at(
      value, key,
      "'" + text + "' is not allowed; use one of " + options + " (" + std::string(doc) + ")");
}

void Binder::numbers(std::string_view key, std::vector<double>& out, const std::vector<double>& def,
                     std::size_t count, double min, double max, std::string_view doc) {
  std::string deflt = "[";
  for (std::size_t i = 0; i < def.size(); ++i) deflt += (i ? ", " : "") + format_number(def[i]);
  deflt += "]";
  impl_->declare(key, "list of " + std::to_string(count) + " numbers", deflt, range_text(min, max),
                 doc);
  out = def;
  const YAML::Node value = impl_->child(key);
  if (!value.IsDefined() || value.IsNull()) return;
  const std::string expect = std::to_string(count) + " numbers, each in " + range_text(min, max) +
                             " (" + std::string(doc) + ")";
  if (!value.IsSequence() || value.size() != count) {
    impl_->fail_at(value, key, "expected a list of " + expect);
  }
  std::vector<double> parsed;
  for (std::size_t i = 0; i < count; ++i) {
    const std::string item_key = std::string(key) + "[" + std::to_string(i) + "]";
    const double number = impl_->read_number(item_key, value[i], "in " + range_text(min, max));
    if (number < min || number > max) {
      impl_->fail_at(value[i], item_key,
                     format_number(number) + " is out of range; allowed " + range_text(min, max));
    }
    parsed.push_back(number);
  }
  out = std::move(parsed);
}

Binder Binder::section(std::string_view key, std::string_view doc) {
  impl_->declare(key, "section", "", "", doc);
  const YAML::Node value = impl_->child(key);
  if (value.IsDefined() && !value.IsNull() && !value.IsMap()) {
    impl_->fail_at(value, key, "expected a mapping of keys (" + std::string(doc) + ")");
  }
  auto impl = std::make_unique<Impl>();
  impl->shared = impl_->shared;
  impl->node = value;
  impl->prefix = impl_->path(key) + ".";
  impl->doc_prefix = impl_->doc_prefix + std::string(key) + ".";
  impl->record_docs = impl_->record_docs;
  return Binder(std::move(impl));
}

void Binder::list(std::string_view key, std::string_view doc,
                  const std::function<void(Binder& item, std::size_t index)>& item) {
  impl_->declare(key, "list", "[]", "", doc);
  impl_->shared->lists.insert(impl_->path(key));
  const YAML::Node value = impl_->child(key);
  auto make_item = [&](const YAML::Node& node, std::size_t index, bool record) {
    auto impl = std::make_unique<Impl>();
    impl->shared = impl_->shared;
    impl->node = node;
    impl->prefix = impl_->path(key) + "[" + std::to_string(index) + "].";
    impl->doc_prefix = impl_->doc_prefix + std::string(key) + "[].";
    impl->record_docs = record;
    return Binder(std::move(impl));
  };
  // The item's keys go into the reference once, whether or not the file has elements.
  {
    Binder documenting_item =
        make_item(YAML::Node(YAML::NodeType::Undefined), 0, impl_->record_docs);
    documenting_item.impl_->prefix = impl_->path(key) + "[].";
    documenting_item.impl_->template_item = true;
    item(documenting_item, 0);
  }
  if (!value.IsDefined() || value.IsNull()) return;
  if (!value.IsSequence()) {
    impl_->fail_at(value, key, "expected a list (- item per line) (" + std::string(doc) + ")");
  }
  for (std::size_t i = 0; i < value.size(); ++i) {
    if (!value[i].IsMap()) {
      impl_->fail_at(value[i], std::string(key) + "[" + std::to_string(i) + "]",
                     "expected a mapping of keys for each list element");
    }
    Binder element = make_item(value[i], i, false);
    item(element, i);
  }
}

bool Binder::present(std::string_view key) const {
  const YAML::Node value = impl_->child(key);
  return value.IsDefined() && !value.IsNull();
}

namespace {

void walk_unknown(const YAML::Node& node, const std::string& prefix,
                  const std::set<std::string>& declared, const std::set<std::string>& lists,
                  const std::string& file) {
  if (!node.IsDefined() || !node.IsMap()) return;
  for (auto it = node.begin(); it != node.end(); ++it) {
    const std::string key = it->first.IsScalar() ? it->first.Scalar() : std::string("?");
    const std::string full = prefix + key;
    if (!declared.contains(full)) {
      // Name the keys that are allowed here, so a typo is one glance from its fix.
      std::string known;
      for (const auto& path : declared) {
        if (path.size() > prefix.size() && path.compare(0, prefix.size(), prefix) == 0 &&
            path.find('.', prefix.size()) == std::string::npos &&
            path.find('[', prefix.size()) == std::string::npos) {
          known += (known.empty() ? "" : ", ") + path.substr(prefix.size());
        }
      }
      std::ostringstream out;
      out << file;
      if (const int line = line_of_node(it->first); line > 0) out << ":" << line;
      out << ": unknown key '" << full << "'";
      if (!known.empty()) out << "; allowed here: " << known;
      out << " (scp-estimatord --print-config-reference lists every key)";
      throw ConfigError(out.str());
    }
    if (lists.contains(full) && it->second.IsSequence()) {
      for (std::size_t i = 0; i < it->second.size(); ++i) {
        walk_unknown(it->second[i], full + "[" + std::to_string(i) + "].", declared, lists, file);
      }
    } else if (it->second.IsMap()) {
      walk_unknown(it->second, full + ".", declared, lists, file);
    }
  }
}

}  // namespace

void Binder::reject_unknown_keys() const {
  // List elements declare "key[i].child"; the documenting pass declares "key[].child" too.
  walk_unknown(impl_->node, impl_->prefix, impl_->shared->declared, impl_->shared->lists,
               impl_->shared->file);
}

bool Binder::is_template() const noexcept {
  return impl_->template_item;
}

int Binder::line_of(std::string_view key) const {
  return line_of_node(impl_->child(key));
}

void Binder::fail(std::string_view key, std::string_view message) const {
  impl_->fail_at(impl_->child(key), key, std::string(message));
}

const std::vector<KeyDoc>& Binder::docs() const {
  return impl_->shared->docs;
}

}  // namespace scp::config
