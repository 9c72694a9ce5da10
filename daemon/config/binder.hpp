#pragma once
// Declare-once configuration, after linuxptp's config table: every key is declared by exactly one
// call that gives its default, its allowed range and one line of documentation. The same calls
// read a YAML document (reporting "key, line, allowed range" on any mistake), reject keys nobody
// declared, and print the reference documentation.

#include <array>
#include <concepts>
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <memory>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "common/names.hpp"

namespace YAML {
class Node;
}

namespace scp::config {

// Every error a user can make in a config file; what() names the key, the line and the remedy.
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct KeyDoc {
  std::string path;   // "estimator.beta"
  std::string type;   // "number", "integer", "bool", "string", "one of a|b", "list"
  std::string deflt;  // default as text
  std::string range;  // "[0.001, 1000]" or ""
  std::string doc;
};

class Binder {
 public:
  // Reads `root` (may be a null node for "all defaults"). `file` is used in messages.
  static Binder reading(const YAML::Node& root, std::string file);
  // Records declarations only (for --print-config-reference); outputs get their defaults.
  static Binder documenting();

  ~Binder();
  Binder(Binder&&) noexcept;
  Binder& operator=(Binder&&) noexcept;

  void number(std::string_view key, double& out, double def, double min, double max,
              std::string_view doc);
  void integer(std::string_view key, std::int64_t& out, std::int64_t def, std::int64_t min,
               std::int64_t max, std::string_view doc);
  // The same into the integer type the setting has (a count, a priority, a seed).
  template <std::integral T>
  requires(!std::same_as<T, std::int64_t>) void integer(std::string_view key, T& out,
                                                        std::type_identity_t<T> def,
                                                        std::type_identity_t<T> min,
                                                        std::type_identity_t<T> max,
                                                        std::string_view doc) {
    std::int64_t value = 0;
    integer(key, value, static_cast<std::int64_t>(def), static_cast<std::int64_t>(min),
            static_cast<std::int64_t>(max), doc);
    out = static_cast<T>(value);
  }
  // A number in [min, max], or `word` (out left empty): e.g. a term held at a value or
  // `estimate`d. `def` is the default as written in the file (`word` or a number).
  void number_or_word(std::string_view key, std::optional<double>& out, std::string_view word,
                      std::string_view def, double min, double max, std::string_view doc);
  void boolean(std::string_view key, bool& out, bool def, std::string_view doc);
  void text(std::string_view key, std::string& out, std::string_view def, std::string_view doc);
  void choice(std::string_view key, std::string& out, std::string_view def,
              std::span<const std::string_view> allowed, std::string_view doc);
  void choice(std::string_view key, std::string& out, std::string_view def,
              std::initializer_list<std::string_view> allowed, std::string_view doc) {
    choice(key, out, def, std::span<const std::string_view>(allowed.begin(), allowed.size()), doc);
  }
  // A choice read into an enumeration, whose table names the allowed values: the reference and
  // the errors list the names, the program sees only the enumeration.
  template <class E, std::size_t N>
  void choice(std::string_view key, E& out, E def, const NameTable<E, N>& allowed,
              std::string_view doc) {
    std::array<std::string_view, N> names{};
    for (std::size_t i = 0; i < N; ++i) names[i] = allowed[i].name;
    std::string text;
    choice(key, text, name_of(allowed, def), std::span<const std::string_view>(names), doc);
    out = *value_of(allowed, text);
  }
  // A fixed-length list of numbers, each in [min, max] (e.g. theta0: 6 numbers).
  void numbers(std::string_view key, std::vector<double>& out, const std::vector<double>& def,
               std::size_t count, double min, double max, std::string_view doc);

  // A nested mapping. Keys declared on the returned binder are "parent.child".
  Binder section(std::string_view key, std::string_view doc);
  // A list of mappings; `item` declares the keys of one element (called once per element, and
  // once with a default-only binder in documenting mode).
  void list(std::string_view key, std::string_view doc,
            const std::function<void(Binder& item, std::size_t index)>& item);
  bool present(std::string_view key) const;
  // True for the one call of a list's `item` callback that only declares the element's keys (for
  // the reference and unknown-key checks); such an element must not be added to the output.
  bool is_template() const noexcept;

  // Raises ConfigError for the first key in the document that nobody declared. Call once, on
  // the root binder, after every declaration.
  void reject_unknown_keys() const;

  // Line (1-based) of a declared key in the file, or 0; for errors found after reading
  // (cross-key checks such as "a frame id used twice").
  int line_of(std::string_view key) const;
  [[noreturn]] void fail(std::string_view key, std::string_view message) const;

  const std::vector<KeyDoc>& docs() const;

 private:
  struct Shared;
  struct Impl;
  explicit Binder(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace scp::config
