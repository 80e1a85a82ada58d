#pragma once
// Reading IDL text for IdlDecoder: the struct and enum blocks of the lab's types.
#include <cpm/rtdb/IdlDecoder.hpp>

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace cpm::rtdb {

/// The IDL of one file, read block by block: every `struct NAME { ... };` and
/// `enum NAME { ... };`; modules, typedefs, forward declarations and the rest are passed over,
/// comments, preprocessor lines and annotations (but @key) ignored.
class IdlParser
{
public:
    using Structs = std::map<std::string, std::vector<IdlDecoder::Member>>;
    using Enums = std::map<std::string, std::vector<std::string>>;

    /// Throws cpm::Error naming file and line for a comment that never ends.
    IdlParser(const std::string& text, std::string file);
    /// Adds each block to structs or enums (a name read again replaces the earlier one). Throws
    /// cpm::Error naming file, line and struct for a block or member it cannot read.
    void read_into(Structs& structs, Enums& enums) const;

private:
    struct Block
    {
        std::string kind, name;  ///< "struct" or "enum"
        size_t open = 0;         ///< where its { is in the cleaned text
        std::string body;        ///< between { and }
    };
    /// The block beginning at i, if one does; i moves past what was read.
    std::optional<Block> block_at(size_t& i) const;
    std::vector<IdlDecoder::Member> members_of(const Block& b) const;
    /// One member declaration, `TYPE NAME [ '[' N ']' ]` (`flat`: its text, spaces collapsed),
    /// found at decl_at in the cleaned text.
    IdlDecoder::Member member(const Block& b, std::string flat, size_t decl_at) const;
    std::string line_of(size_t at) const;

    std::string file_;
    std::string clean_;  ///< the text without comments and annotations, lines kept
};

/// "sequence<T>" or "sequence<T, N>".
struct SequenceType
{
    std::string element;
    std::optional<uint64_t> bound;
};
/// "sequence<T>" or "sequence<T, N>" (spaces anywhere between); nullopt for any other type.
std::optional<SequenceType> sequence_of(const std::string& type);

}  // namespace cpm::rtdb
