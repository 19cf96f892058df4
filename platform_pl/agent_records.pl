:- module(agent_records,
          [ agent_export/3,             % +Node, +Name, -Record
            agent_install/4,            % +Node, +Record, +Status, -Name
            agent_install/5             % +Node, +Record, +Status, -Name, +Options
          ]).
:- use_module(agent_registry,
              [ agent_registered/3, agent_module/3, agent_register/5,
                agent_register_state/3 ]).
:- use_module(agent_code,
              [ replace_guid/4, install_clauses/2, install_preds/2, module_clauses/3 ]).
:- autoload(library(lists), [member/2]).

/** <module> An agent's record: exported from a node, installed on one

An agent's record is a self-contained copy of it: everything needed to
install it on another node, save it to a file or clone it, as the term
agent(Name, Handler, Kind, Tokens, Payload, Preds, Clauses, Hops). A
move, a clone, custody, checkpoints and saved files all go through
agent_export/3 and agent_install/4,5. The registry's part of an agent
is agent_registry.pl's, its module's clauses agent_code.pl's; this
module puts the two together and takes them apart, and checks the shape
of a record before anything of it is installed.
*/

%!  agent_export(+Node, +Name, -Record) is det.
%
%   Record is a self-contained copy of the agent: everything needed to
%   install it on another node, save it to a file or clone it:
%   agent(Name, Handler, Kind, Tokens, Payload, Preds, Clauses, Hops).
%   Tokens are the agent's own, for uses inside this process (custody,
%   checkpoints): a record that leaves it carries none (migration.pl
%   sends [], persist.pl saves []).
%
%   @error existence_error(agent, Name)

agent_export(Node, Name, agent(Name, Handler, Kind, Tokens, Payload,
                               Preds, Clauses, Hops)) :-
    agent_registered(Node, Name, registered(Handler, Kind, Tokens, Payload, Hops)),
    agent_module(Node, Name, M),
    module_clauses(M, Preds, Clauses).

%!  agent_install(+Node, +Record, +Status, -Name) is det.
%
%   Install an agent from its Record with Status. If Record's name is
%   taken on Node, Name is the name of Record unless the record asks for
%   a fresh one: rename(Base) as name makes a fresh name Base_N and
%   replaces the old name by it in all clauses.
%
%   @error permission_error(create, agent, Name) if the name is taken.
%   @error type_error(agent_record, Record) for a malformed record.

agent_install(Node, Record, Status, Name) :-
    agent_install(Node, Record, Status, Name, []).

%!  agent_install(+Node, +Record, +Status, -Name, +Options) is det.
%
%   As agent_install/4. Options:
%
%     - max_agents(+Max)  refuse the agent if Node holds Max agents
%                         already (an integer or `infinite`, the
%                         default). Counted and registered under the
%                         registry mutex, so simultaneous arrivals never
%                         make more than Max.
%     - peer(+Peer)       the peer the agent arrives from (a ground
%                         term; default `local`): its property peer(P)
%     - max_per_peer(+Max) refuse the agent if Node holds Max agents of
%                         Peer already (default `infinite`; never for
%                         `local`), counted as max_agents is.
%
%   @error resource_error(agents) if Node holds Max agents.
%   @error resource_error(peer_agents) if it holds Max agents of Peer.

agent_install(Node, Record, Status, Name, Options) :-
    check_record(Record),
    Record = agent(Name0, Handler, Kind, Tokens, Payload, Preds, Clauses0, Hops),
    agent_register(Node, Name0, entry(Handler, Kind), Options, Name),
    (   Name0 = rename(Old, _)
    ->  replace_guid(Clauses0, Old, Name, Clauses)
    ;   Clauses = Clauses0
    ),
    agent_module(Node, Name, M),
    install_preds(M, Preds),
    install_clauses(M, Clauses),
    agent_register_state(Node, Name, state(Tokens, Payload, Hops, Status)).

check_record(Record) :-
    (   Record = agent(Name, Handler, Kind, Tokens, Payload, Preds, Clauses, Hops),
        ( atom(Name) ; Name = rename(O, B), atom(O), atom(B) ),
        atom(Handler),
        memberchk(Kind, [mobile, static]),
        is_list(Tokens), ground(Tokens),
        is_list(Payload),
        is_list(Preds),
        forall(member(P, Preds), (P = F/A, atom(F), integer(A), A >= 0)),
        is_list(Clauses),
        forall(member(C, Clauses), valid_clause(C)),
        is_list(Hops)
    ->  true
    ;   throw(error(type_error(agent_record, Record), _))
    ).

valid_clause((H:-_)) :-
    !,
    valid_head(H).
valid_clause(H) :-
    valid_head(H).

%   Not qualified, and no control construct: a head (a:-b) would be
%   asserted as a rule.
valid_head(H) :-
    callable(H),
    \+ H = (_:_),
    functor(H, F, A),
    \+ memberchk(F/A, [ (:-)/2, (:-)/1, (?-)/1, (-->)/2, (',')/2, (;)/2,
                        (->)/2, (*->)/2, (\+)/1, (@)/2 ]).
