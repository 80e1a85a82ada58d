#include <cpm/Security.hpp>

#include <cpm/nodes.hpp>
#include <cpm/topics.hpp>

#include <cpm/ChildProcess.hpp>
#include <cpm/Error.hpp>
#include <cpm/read_text_file.hpp>

#include <tinyxml2.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fnmatch.h>
#include <fstream>
#include <sstream>
#include <sys/stat.h>
#include <unistd.h>

namespace fs = std::filesystem;

namespace cpm::security {

namespace {

constexpr const char* kOrganisation = "cpm lab";

std::string find_openssl()
{
    std::string found = program_on_path("openssl");
    if (found.empty()) throw Error("the openssl command is not installed (Debian package openssl; ./lab installs it)");
    return found;
}

/// Runs openssl with these arguments in `dir`; throws naming `what` with openssl's own message.
void openssl(const std::vector<std::string>& args, const std::string& what)
{
    static const std::string program = find_openssl();
    const fs::path log = fs::temp_directory_path() / ("cpm_openssl_" + std::to_string(::getpid()) + ".log");
    std::vector<std::string> argv{program};
    argv.insert(argv.end(), args.begin(), args.end());
    ExitStatus end;
    {
        ChildProcess child({.argv = argv, .stdout_path = log.string(), .stderr_path = log.string()});
        auto ended = child.wait(std::chrono::seconds(60));
        end = ended ? *ended : child.stop();
    }
    std::string output;
    if (std::ifstream in(log); in) output.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    std::error_code ignored;
    fs::remove(log, ignored);
    if (!end.ok()) throw Error(what + ": openssl " + args.front() + " " + end.describe() + (output.empty() ? "" : ": " + output));
}

void write_file(const fs::path& path, const std::string& text, bool secret = false)
{
    std::ofstream out(path, std::ios::trunc);
    out << text;
    out.close();
    if (!out) throw Error(path.string() + ": cannot write");
    if (secret) fs::permissions(path, fs::perms::owner_read | fs::perms::owner_write);
}

/// Local time, as Fast DDS reads a permissions validity (it has no time zone).
std::string local_time(std::time_t t)
{
    std::tm tm{};
    localtime_r(&t, &tm);
    char text[32];
    std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%S", &tm);
    return text;
}

bool valid_name(const std::string& name)
{
    if (name.empty() || name.size() > 64) return false;
    for (char c : name) {
        if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_' && c != '-') return false;
    }
    return true;
}

bool valid_topic_pattern(const std::string& topic)
{
    if (topic.empty() || topic.size() > 256) return false;
    for (char c : topic) {
        if (!std::isalnum(static_cast<unsigned char>(c)) && std::string("_-/*?.").find(c) == std::string::npos) return false;
    }
    return true;
}

void new_ca(const fs::path& dir, const std::string& stem, const std::string& common_name, int days)
{
    const std::string key = (dir / (stem + ".key.pem")).string(), cert = (dir / (stem + ".cert.pem")).string();
    openssl({"ecparam", "-name", "prime256v1", "-genkey", "-noout", "-out", key}, "the " + common_name + "'s key");
    fs::permissions(key, fs::perms::owner_read | fs::perms::owner_write);
    // No keyUsage: a CA certificate limited to keyCertSign cannot sign S/MIME (the governance).
    openssl({"req", "-x509", "-new", "-key", key, "-sha256", "-days", std::to_string(days), "-subj",
             "/O=" + std::string(kOrganisation) + "/CN=" + common_name, "-addext", "basicConstraints=critical,CA:TRUE,pathlen:0",
             "-out", cert},
            "the " + common_name + "'s certificate");
}

void sign(const fs::path& dir, const fs::path& in, const fs::path& out)
{
    openssl({"smime", "-sign", "-text", "-in", in.string(), "-out", out.string(), "-signer",
             (dir / "permissions_ca.cert.pem").string(), "-inkey", (dir / "permissions_ca.key.pem").string()},
            "signing " + in.filename().string());
}

std::string governance_xml()
{
    // One rule for every domain cpm uses; one for every topic: nobody joins, reads or writes
    // without a certificate from the lab and a grant, and everything on the wire is encrypted.
    return R"(<?xml version="1.0" encoding="UTF-8"?>
<!-- A cpm lab's governance (cpm security init): signed by the lab's permissions CA. -->
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance">
  <domain_access_rules>
    <domain_rule>
      <domains>
        <id_range><min>0</min><max>232</max></id_range>
      </domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>NONE</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
)";
}

std::vector<std::string> with_builtin(std::vector<std::string> topics, const std::vector<std::string>& builtin)
{
    for (const auto& t : builtin) {
        if (std::find(topics.begin(), topics.end(), t) == topics.end()) topics.push_back(t);
    }
    return topics;
}

/// A node that may subscribe topics may also ask the history for their past: it publishes
/// historyRequest, subscribes historyReply (lists, errors) and historyReply/T for each topic T it
/// may subscribe (the samples of T: the history answers there in a secured lab).
Grant with_history(const Grant& grant)
{
    Grant out = grant;
    if (grant.subscribe.empty()) return out;
    out.publish = with_builtin(out.publish, nodes::find("history_client").publish);
    std::vector<std::string> replies{topics::history_reply.name};
    for (const auto& t : grant.subscribe) {
        if (!topics::is_history_control(t) && t.rfind(topics::history_reply.name, 0) != 0) replies.push_back(topics::history_reply_topic(t));
    }
    out.subscribe = with_builtin(out.subscribe, replies);
    return out;
}

std::string topics_xml(const char* element, const std::vector<std::string>& topics)
{
    if (topics.empty()) return "";
    std::string out = std::string("      <") + element + ">\n        <topics>\n";
    for (const auto& t : topics) out += "          <topic>" + t + "</topic>\n";  // checked: no XML markup
    return out + "        </topics>\n      </" + element + ">\n";
}

std::string require(const fs::path& dir, const char* name)
{
    const fs::path p = dir / name;
    if (!fs::is_regular_file(p)) throw Error(dir.string() + ": not a cpm node's security folder: " + name + " is missing (cpm security add-node makes it)");
    return fs::absolute(p).string();
}

/// The topics a node's permissions.xml grants for publish or subscribe (in its allow rules).
std::vector<std::string> granted(const std::string& permissions_xml, bool publish)
{
    tinyxml2::XMLDocument doc;
    std::vector<std::string> out;
    if (doc.LoadFile(permissions_xml.c_str()) != tinyxml2::XML_SUCCESS) return out;
    const auto* grant = doc.RootElement() ? doc.RootElement()->FirstChildElement("permissions") : nullptr;
    grant = grant ? grant->FirstChildElement("grant") : nullptr;
    for (const auto* rule = grant ? grant->FirstChildElement("allow_rule") : nullptr; rule; rule = rule->NextSiblingElement("allow_rule")) {
        for (const auto* kind = rule->FirstChildElement(publish ? "publish" : "subscribe"); kind;
             kind = kind->NextSiblingElement(publish ? "publish" : "subscribe")) {
            const auto* topics = kind->FirstChildElement("topics");
            for (const auto* t = topics ? topics->FirstChildElement("topic") : nullptr; t; t = t->NextSiblingElement("topic")) {
                if (t->GetText()) out.emplace_back(t->GetText());
            }
        }
    }
    return out;
}

std::string subject_of(const std::string& permissions_xml)
{
    tinyxml2::XMLDocument doc;
    if (doc.LoadFile(permissions_xml.c_str()) != tinyxml2::XML_SUCCESS) return "?";
    const auto* p = doc.RootElement() ? doc.RootElement()->FirstChildElement("permissions") : nullptr;
    const auto* g = p ? p->FirstChildElement("grant") : nullptr;
    const auto* s = g ? g->FirstChildElement("subject_name") : nullptr;
    return s && s->GetText() ? s->GetText() : "?";
}

}  // namespace

void init_lab(const std::string& dir_text, int days)
{
    if (days < 1 || days > 36500) throw Error("--days " + std::to_string(days) + ": expected 1..36500");
    const fs::path dir(dir_text);
    if (fs::exists(dir / "identity_ca.key.pem") || fs::exists(dir / "permissions_ca.key.pem")) {
        throw Error(dir_text + ": already holds a lab's CAs (never overwritten; add nodes with cpm security add-node)");
    }
    std::error_code ec;
    fs::create_directories(dir / "nodes", ec);
    if (ec) throw Error(dir_text + ": cannot create the folder: " + ec.message());
    fs::permissions(dir, fs::perms::owner_all, ec);
    new_ca(dir, "identity_ca", "cpm identity CA", days);
    new_ca(dir, "permissions_ca", "cpm permissions CA", days);
    write_file(dir / "governance.xml", governance_xml());
    sign(dir, dir / "governance.xml", dir / "governance.p7s");
}

std::string add_node(const std::string& dir_text, const std::string& name, const Grant& grant)
{
    const fs::path dir(dir_text);
    for (const char* f : {"identity_ca.key.pem", "identity_ca.cert.pem", "permissions_ca.key.pem", "permissions_ca.cert.pem", "governance.p7s"}) {
        if (!fs::is_regular_file(dir / f)) throw Error(dir_text + ": not a cpm lab's security folder (" + f + " is missing; make one with cpm security init)");
    }
    if (!valid_name(name)) throw Error("node name '" + name + "': use 1..64 letters, digits, - and _");
    if (grant.days < 1 || grant.days > 36500) throw Error("--days " + std::to_string(grant.days) + ": expected 1..36500");
    for (const auto* list : {&grant.publish, &grant.subscribe}) {
        for (const auto& t : *list) {
            if (!valid_topic_pattern(t)) throw Error("topic '" + t + "': expected a topic name or pattern (letters, digits, _ - / . and the wildcards * ?)");
        }
    }
    const fs::path node = dir / "nodes" / name;
    if (fs::exists(node)) throw Error(node.string() + ": node '" + name + "' exists already (remove its folder to issue it again)");
    fs::create_directories(node);
    try {
        const auto key = (node / "key.pem").string(), csr = (node / "cert.csr").string(), cert = (node / "cert.pem").string();
        openssl({"ecparam", "-name", "prime256v1", "-genkey", "-noout", "-out", key}, "node " + name + "'s key");
        fs::permissions(key, fs::perms::owner_read | fs::perms::owner_write);
        const std::string subject_slashes = "/O=" + std::string(kOrganisation) + "/CN=" + name;
        openssl({"req", "-new", "-key", key, "-subj", subject_slashes, "-out", csr}, "node " + name + "'s certificate request");
        openssl({"x509", "-req", "-in", csr, "-CA", (dir / "identity_ca.cert.pem").string(), "-CAkey",
                 (dir / "identity_ca.key.pem").string(), "-CAcreateserial", "-CAserial", (dir / "identity_ca.srl").string(),
                 "-sha256", "-days", std::to_string(grant.days), "-out", cert},
                "node " + name + "'s certificate");
        fs::remove(csr);
        // The subject exactly as Fast DDS compares it: RFC 2253, most specific first.
        const std::string subject = "CN=" + name + ",O=" + kOrganisation;
        const std::time_t now = std::time(nullptr);
        const Grant full = with_history(grant);
        const std::string permissions =
            std::string(R"(<?xml version="1.0" encoding="UTF-8"?>
<!-- Node ')") + name + R"(' of a cpm lab (cpm security add-node): signed by the lab's permissions CA. -->
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance">
  <permissions>
    <grant name=")" + name + R"(">
      <subject_name>)" + subject + R"(</subject_name>
      <validity>
        <not_before>)" + local_time(now - 86400) + R"(</not_before>
        <not_after>)" + local_time(now + std::time_t(grant.days) * 86400) + R"(</not_after>
      </validity>
      <allow_rule>
        <domains>
          <id_range><min>0</min><max>232</max></id_range>
        </domains>
)" + topics_xml("publish", with_builtin(full.publish, nodes::builtin_publish())) +
            topics_xml("subscribe", with_builtin(full.subscribe, nodes::builtin_subscribe())) + R"(      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
)";
        write_file(node / "permissions.xml", permissions);
        sign(dir, node / "permissions.xml", node / "permissions.p7s");
        for (const char* f : {"identity_ca.cert.pem", "permissions_ca.cert.pem", "governance.p7s"}) fs::copy_file(dir / f, node / f);
    } catch (...) {
        std::error_code ignored;
        fs::remove_all(node, ignored);  // no half-made node left behind
        throw;
    }
    return node.string();
}

NodeFiles node_files(const std::string& node_dir)
{
    const fs::path dir(node_dir);
    if (!fs::is_directory(dir)) throw Error(node_dir + ": no such folder (a node's security folder: cpm security add-node LAB NAME makes LAB/nodes/NAME)");
    NodeFiles f;
    f.identity_ca = require(dir, "identity_ca.cert.pem");
    f.certificate = require(dir, "cert.pem");
    f.private_key = require(dir, "key.pem");
    f.permissions_ca = require(dir, "permissions_ca.cert.pem");
    f.governance = require(dir, "governance.p7s");
    f.permissions = require(dir, "permissions.p7s");
    f.permissions_xml = require(dir, "permissions.xml");
    return f;
}

std::vector<std::pair<std::string, std::string>> participant_properties(const NodeFiles& f)
{
    const std::string pki = "dds.sec.auth.builtin.PKI-DH.", access = "dds.sec.access.builtin.Access-Permissions.";
    return {
        {"dds.sec.auth.plugin", "builtin.PKI-DH"},
        {pki + "identity_ca", "file://" + f.identity_ca},
        {pki + "identity_certificate", "file://" + f.certificate},
        {pki + "private_key", "file://" + f.private_key},
        {"dds.sec.access.plugin", "builtin.Access-Permissions"},
        {access + "permissions_ca", "file://" + f.permissions_ca},
        {access + "governance", "file://" + f.governance},
        {access + "permissions", "file://" + f.permissions},
        {"dds.sec.crypto.plugin", "builtin.AES-GCM-GMAC"},
    };
}

std::string why_not_allowed(const NodeFiles& files, const std::string& topic, bool publish)
{
    const auto patterns = granted(files.permissions_xml, publish);
    for (const auto& p : patterns) {
        if (::fnmatch(p.c_str(), topic.c_str(), 0) == 0) return "";
    }
    std::string list;
    for (const auto& p : patterns) list += (list.empty() ? "" : ", ") + p;
    return "this node (" + subject_of(files.permissions_xml) + ") may not " + (publish ? "publish" : "subscribe") + " '" + topic +
           "': its permissions (" + files.permissions_xml + ") allow " + (publish ? "publishing " : "subscribing ") +
           (list.empty() ? "nothing" : list);
}

}  // namespace cpm::security
