:- module(agents,
          [ agent_create/4,             % ?Name, +Handler, +Options, +Node
            agent_execute/4,            % +Node, +Name, +Link, +Event
            agent_purge/2,              % +Node, +Name
            agent_exists/2,             % ?Node, ?Name
            agent_property/3,           % ?Node, ?Name, ?Property
            agent_list/2,               % +Node, -Agents
            agent_add_payload/3,        % +Node, +Name, +Preds
            agent_add_facts/3,          % +Node, +Name, +Facts
            agent_remove_payload/3,     % +Node, +Name, +Preds
            agent_add_tokens/3,         % +Node, +Name, +Tokens
            agent_remove_tokens/3,      % +Node, +Name, +Tokens
            agent_module/3,             % +Node, +Name, -Module
            agent_export/3,             % +Node, +Name, -Record
            agent_install/4,            % +Node, +Record, +Status, -Name
            agent_install/5,            % +Node, +Record, +Status, -Name, +Options
            agent_remove/2,             % +Node, +Name
            agent_set_status/3,         % +Node, +Name, +Status
            agent_status/3,             % +Node, +Name, -Status
            agent_take_idle/2,          % +Node, +Name
            agent_hop_times/3,          % +Node, +Name, -Millis
            agent_record_hop/3,         % +Node, +Name, +Hop
            agent_fresh_name/3,         % +Node, +Base, -Name
            current_agent/1,            % -Name
            replace_guid/4,             % +Term0, +From, +To, -Term
            with_agents_locked/1,       % :Goal
            agent_notify/3              % +Event, +Node, +Name
          ]).
:- use_module(node, [node_property/2]).
:- use_module(agent_registry,
              [ with_agents_locked/1, agent_notify/3, agent_module/3, agent_exists/2,
                agent_property/3, agent_list/2, agent_status/3, agent_set_status/3,
                agent_take_idle/2, agent_fresh_name/3, agent_register/5,
                agent_register_state/3, agent_add_tokens/3, agent_remove_tokens/3,
                agent_hop_times/3, agent_record_hop/3 ]).
:- use_module(agent_code,
              [ replace_guid/4, handler_clauses/3, install_clauses/2, agent_add_payload/3,
                agent_add_facts/3, agent_remove_payload/3 ]).
:- use_module(agent_records, [agent_export/3, agent_install/4, agent_install/5]).
:- use_module(agent_execution,
              [agent_execute/4, current_agent/1, agent_purge/2, agent_remove/2]).
:- autoload(library(error), [must_be/2, existence_error/2]).
:- autoload(library(option), [option/2, option/3]).

/** <module> Agents on a node: registry, code, payload, tokens, threads

An agent is a name, a handler predicate, a kind (mobile or static), a
list of tokens and a private module that holds its code: the handler's
clauses and the payload facts, with the atom `guid` replaced by the
agent's name (on terms, never on text). Goals in the handler run in that
module, which inherits from `user`, so helper predicates of the program
are visible and the agent's own asserts land in its module, i.e. they
are the agent's state and travel with it.

A running agent has a thread. When its handler returns the agent stays
on the node, idle, until it is executed again, moved or purged.

This module is the agents' face: it makes an agent (agent_create/4) and
re-exports the rest from the modules that hold it, so that callers load
one module:

  | module               | what |
  |----------------------|------|
  | agent_registry.pl    | the agents' records, the registry mutex, agents:agent_changed/3 |
  | agent_code.pl        | an agent's module: `guid` replaced, clauses installed, payload |
  | agent_records.pl     | an agent's record: agent_export/3, agent_install/4,5 |
  | agent_execution.pl   | the handler in a pool worker, current_agent/1, purge and removal |

The agents' modules are written only by these (agent_code.pl's module
comment says why that is by design); other platform modules change an
agent only through the predicates exported here.
*/

%!  agent_create(?Name, +Handler, +Options, +Node) is det.
%
%   Register a new agent on Node without starting it. An unbound Name is
%   bound to a fresh one. The clauses of Handler/N (N >= 3) in the
%   source module are copied into the agent's module with `guid`
%   replaced by Name. Options:
%
%     - kind(+Kind)        `mobile` (default) or `static`
%     - tokens(+List)      tokens the agent carries (default: the node's)
%     - payload(+Preds)    payload predicates, as for agent_add_payload/3
%     - module(+Module)    where Handler and payload are defined
%                          (default `user`)
%     - events(+List)      the Handler/Arity events peers may post to it
%                          (default: every arity of Handler it carries;
%                          kept as the fact '$agent_events'(List) in its
%                          module, so it travels with it)
%
%   @error permission_error(create, agent, Name) if the name is taken.
%   @error existence_error(handler, Handler/3) if Handler has no clauses.

agent_create(Name, Handler0, Options, Node) :-
    must_be(list, Options),
    strip_handler(Handler0, Options, SrcModule, Handler),
    option(kind(Kind), Options, mobile),
    must_be(oneof([mobile, static]), Kind),
    (   option(tokens(Tokens), Options)
    ->  must_be(list, Tokens)
    ;   node_property(Node, tokens(Tokens))
    ->  true
    ;   existence_error(platform, Node)
    ),
    handler_clauses(SrcModule, Handler, Templates),
    (   Templates == []
    ->  existence_error(handler, Handler/3)
    ;   true
    ),
    (   var(Name)
    ->  true
    ;   must_be(atom, Name)
    ),
    agent_register(Node, Name, entry(Handler, Kind), [], Name),
    agent_module(Node, Name, M),
    replace_guid(Templates, guid, Name, Clauses),
    install_clauses(M, Clauses),
    (   option(events(Events), Options)
    ->  must_be(list, Events),
        install_clauses(M, ['$agent_events'(Events)])
    ;   true
    ),
    agent_register_state(Node, Name, state(Tokens, [], [], idle)),
    (   option(payload(Preds), Options)
    ->  agent_add_payload(Node, Name, Preds)
    ;   agent_notify(saved, Node, Name)
    ).

strip_handler(M:H, _, M, H) :-
    !,
    must_be(atom, H).
strip_handler(H, Options, M, H) :-
    must_be(atom, H),
    option(module(M), Options, user).
