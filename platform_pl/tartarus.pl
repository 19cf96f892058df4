:- module(tartarus,
          [ start_tartarus/2,           % +Ip, +Port
            start_tartarus/3,           % +Ip, +Port, +Token
            start_tartarus/4,           % +Ip, +Port, +Token, +Options
            close_tartarus/0,
            reset_tartarus/0,
            set_token/1,                % +Token
            get_tartarus_details/2,     % -Ip, -Port
            create_mobile_agent/3,      % ?Name, +Handler, +Tokens
            create_mobile_agent/4,      % ?Name, +(Ip,Port), +Handler, +Tokens
            create_static_agent/3,      % ?Name, +Handler, +Tokens
            create_static_agent/4,      % ?Name, +(Ip,Port), +Handler, +Tokens
            execute_agent/3,            % +Name, +(Ip,Port), +Handler
            execute_agent/4,            % +Name, +(Ip,Port), +Handler, +Event
            add_payload/2,              % +Name, +Preds
            remove_payload/2,           % +Name, +Preds
            add_token/2,                % +Name, +Tokens
            remove_token/2,             % +Name, +Tokens
            move_agent/2,               % +Name, +(Ip,Port)
            clone_agent/3,              % +Name, +(Ip,Port), -Clone
            post_agent/3,               % +platform, +(Ip,Port), +Message
            agent_post/3,               % +platform, +(Ip,Port), +Message
            purge_agent/1,              % +Name
            list_agents/0,
            list_agents/1,              % +(Ip,Port) or -Names
            list_agent/0,
            list_agent/1,               % +(Ip,Port) or -Names
            isexist_agent/3,            % ?Name, ?(Ip,Port), ?Handler
            save_agent/2,               % +Name, +File
            assert_file_to_tartarus/1,  % +File
            save_tartarus_state/1,      % +File
            load_tartarus_state/1,      % +File
            agent_hop_times/2,          % +Name, -Millis
            agent_hop_statistics/2      % +Name, -Stats
          ]).
:- reexport(node,
            [ node_start/3, node_stop/1, node_property/2, current_node/1,
              with_node/2, node_set_default/1, node_set_tokens/2,
              platform_shutdown/0 ]).
:- reexport(migration, [agent_move/3, agent_clone/4, agent_resolve/2]).
:- reexport(messages,
            [ agent_post/5, platform_event/1, remote_agents/3,
              remote_execute/4 ]).
:- reexport(codeload, [load_program/1, load_program_at/3, load_program_text/4]).
:- reexport(agents, [agent_property/3, current_agent/1]).
:- use_module(agents).
:- use_module(persist).
:- use_module(transport, [address_normalize/2]).
:- use_module(node, [node_for_address/2]).
:- use_module(platform_errors, [message_text/2]).
:- autoload(library(error), [must_be/2, existence_error/2, domain_error/2]).
:- autoload(library(lists), [member/2, sum_list/2, max_list/2, min_list/2,
                             nth0/3]).

/** <module> The Tartarus-style API of the dfrl agent platform

Load this file (`swipl platform_pl/tartarus.pl`, consult/1 or
use_module/1) to get the whole platform with the API a Tartarus user
knows: start_tartarus/3, create_mobile_agent/4, add_payload/2,
move_agent/2, clone_agent/3, post_agent/3 and friends. Agent programs
written for Tartarus run unchanged:

```
:- dynamic hello/3, visited/2.
visited(guid, []).

hello(guid, (Ip,Port), main) :-
    format("agent guid at ~w:~w~n", [Ip, Port]),
    retract(visited(guid, L)), assertz(visited(guid, [Port|L])),
    (   Port =:= 7003 -> true ; Next is Port + 1, move_agent(guid, (Ip,Next)) ).
```

The native API (node_start/3, agent_move/3, load_program_at/3, ...) is
re-exported too. Differences with Tartarus, all on purpose:

  - move_agent/2 raises an error when the move did not happen (refused
    token, unreachable node, timeout); the agent then stays where it was.
  - An agent's code and payload live in a module of its own, so asserts
    in a handler update the agent's own state; use user:Fact for a fact
    that must stay on the node.
  - Posted messages reach only a registered agent's handler or a declared
    platform_event/1; a peer can never make a platform call an arbitrary
    goal.
  - A platform binds only the address it is given, and rejects ports
    outside 0..65535.
*/

		 /*******************************
		 *           PLATFORM		*
		 *******************************/

%!  start_tartarus(+Ip, +Port) is det.
%!  start_tartarus(+Ip, +Port, +Token) is det.
%
%   Start a platform listening on Ip:Port and make it the default
%   platform of this process. Port 0 lets the OS choose (see
%   get_tartarus_details/2). Without Token the platform is open: it
%   accepts any agent.

start_tartarus(Ip, Port) :-
    node_start(Ip:Port, _, [default(true)]).
start_tartarus(Ip, Port, Token) :-
    must_be(ground, Token),
    node_start(Ip:Port, _, [token(Token), default(true)]).

%!  start_tartarus(+Ip, +Port, +Token, +Options) is det.
%
%   As start_tartarus/3, with further options of node_start/3. For a
%   platform that speaks mutual TLS with its peers: tls(Dir), where Dir
%   holds ca.crt, node.crt and node.key (`dfrl certs node NAME CA_DIR
%   --out Dir`), and optionally tls_peers(Names), the certificate names
%   that may send it agents or code:
%
%   ```
%   ?- start_tartarus(localhost, 5000, 1111, [tls('certs/alpha')]).
%   ```

start_tartarus(Ip, Port, Token, Options) :-
    must_be(ground, Token),
    must_be(list, Options),
    node_start(Ip:Port, _, [token(Token), default(true)|Options]).

%!  close_tartarus is det.
%
%   Stop the current platform: its agents are purged and its port closed.

close_tartarus :-
    current_node(Node),
    node_stop(Node).

%!  reset_tartarus is det.
%
%   Purge every agent of the current platform; the platform keeps running.

reset_tartarus :-
    current_node(Node),
    forall(agent_exists(Node, Name), catch(agent_purge(Node, Name), _, true)).

%!  set_token(+Token) is det.
%
%   Make Token the (only) token of the current platform.

set_token(Token) :-
    must_be(ground, Token),
    current_node(Node),
    node_set_tokens(Node, [Token]).

%!  get_tartarus_details(-Ip, -Port) is det.
%
%   Address of the current platform.

get_tartarus_details(Ip, Port) :-
    current_node(Node),
    node_property(Node, address(Ip:Port)).

		 /*******************************
		 *            AGENTS		*
		 *******************************/

%!  create_mobile_agent(?Name, +Link, +Handler, +Tokens) is det.
%!  create_mobile_agent(?Name, +Handler, +Tokens) is det.
%
%   Register a mobile agent on the platform at Link ((Ip,Port) of a
%   platform in this process), or on the current one. Handler clauses
%   Handler(guid, Link, Event) are copied with `guid` replaced by Name.
%   An unbound Name gets a fresh name. Tokens is the agent's token list
%   ([] = the platform's tokens). The agent does not run until
%   execute_agent/3 or move_agent/2. The 3-argument form also accepts
%   (Name, Link, Handler).
%
%   @error existence_error(platform, Link) if no platform of this
%   process listens on Link.

create_mobile_agent(Name, Link, Handler, Tokens) :-
    create_agent(mobile, Name, Link, Handler, Tokens).
create_mobile_agent(Name, A2, A3) :-
    create3(mobile, Name, A2, A3).

%!  create_static_agent(?Name, +Link, +Handler, +Tokens) is det.
%!  create_static_agent(?Name, +Handler, +Tokens) is det.
%
%   As create_mobile_agent/4 for an agent that never moves.

create_static_agent(Name, Link, Handler, Tokens) :-
    create_agent(static, Name, Link, Handler, Tokens).
create_static_agent(Name, A2, A3) :-
    create3(static, Name, A2, A3).

create3(Kind, Name, A2, A3) :-
    (   is_link(A2)
    ->  create_agent(Kind, Name, A2, A3, [])
    ;   current_node(Node),
        node_property(Node, link(Link)),
        create_agent(Kind, Name, Link, A2, A3)
    ).

is_link((_,_)).
is_link(_:_).

create_agent(Kind, Name, Link, Handler, Tokens0) :-
    must_be(list, Tokens0),
    link_node(Link, Node),
    (   Tokens0 == []
    ->  TokOpts = []
    ;   TokOpts = [tokens(Tokens0)]
    ),
    agent_create(Name, Handler, [kind(Kind)|TokOpts], Node).

link_node(Link, Node) :-
    address_normalize(Link, Address),
    (   node_for_address(Address, Node)
    ->  true
    ;   existence_error(platform, Link)
    ).

%!  execute_agent(+Name, +Link, +Handler) is det.
%!  execute_agent(+Name, +Link, +Handler, +Event) is det.
%
%   Start agent Name on the platform at Link (in this process or
%   remote): its handler runs with Event (default `main`).
%
%   @error existence_error(agent, Name)
%   @error domain_error(handler_of(Name), Handler) if Name's handler
%   differs.

execute_agent(Name, Link, Handler) :-
    execute_agent(Name, Link, Handler, main).
execute_agent(Name, Link, Handler, Event) :-
    must_be(atom, Name),
    address_normalize(Link, Address),
    (   node_for_address(Address, Node)
    ->  (   agent_property(Node, Name, handler(H))
        ->  (   H == Handler
            ->  true
            ;   domain_error(handler_of(Name), Handler)
            )
        ;   existence_error(agent, Name)
        ),
        node_property(Node, link(L)),
        agent_execute(Node, Name, L, Event)
    ;   remote_execute(Address, Name, Event, [])
    ).

%!  add_payload(+Name, +Preds) is det.
%
%   Preds is a list of (Pred,Arity) or Pred/Arity: facts Pred(guid, ...)
%   asserted in `user` are copied into the agent and travel with it.

add_payload(Name, Preds) :-
    current_node(Node),
    agent_add_payload(Node, Name, Preds).

%!  remove_payload(+Name, +Preds) is det.

remove_payload(Name, Preds) :-
    current_node(Node),
    agent_remove_payload(Node, Name, Preds).

%!  add_token(+Name, +Tokens) is det.

add_token(Name, Tokens) :-
    current_node(Node),
    agent_add_tokens(Node, Name, Tokens).

%!  remove_token(+Name, +Tokens) is det.

remove_token(Name, Tokens) :-
    current_node(Node),
    agent_remove_tokens(Node, Name, Tokens).

%!  move_agent(+Name, +Link) is det.
%
%   Move agent Name from the current platform to the platform at Link
%   ((Ip,Port)); its handler restarts there with Event `main`. Raises an
%   error (and the agent stays) if the move did not happen.

move_agent(Name, Link) :-
    agent_move(Name, Link, []).

%!  clone_agent(+Name, +Link, -Clone) is det.
%
%   Send a copy of Name, named Clone, to the platform at Link, where it
%   starts with Event `main`.

clone_agent(Name, Link, Clone) :-
    agent_clone(Name, Link, Clone, []).

%!  post_agent(+Platform, +Link, +Message) is det.
%!  agent_post(+Platform, +Link, +Message) is det.
%
%   Message is [Handler, Agent, AgentLink | Args]: the platform at Link
%   calls Handler(Agent, AgentLink, Args...) for its agent Agent. The
%   first argument is the atom `platform`, as in Tartarus.

post_agent(platform, Link, Message) :-
    must_be(list, Message),
    (   Message = [Handler, Agent, ALink | Args]
    ->  agent_post(Link, Agent, Handler, ALink, Args)
    ;   domain_error(agent_message, Message)
    ).

agent_post(Platform, Link, Message) :-
    post_agent(Platform, Link, Message).

%!  purge_agent(+Name) is det.
%
%   Stop agent Name and forget it.

purge_agent(Name) :-
    current_node(Node),
    agent_purge(Node, Name).

%!  list_agents is det.
%!  list_agents(+Link) is det.
%!  list_agents(-Names) is det.
%
%   Print the agents on the current platform, or, as Tartarus does, on
%   the platform at Link = (Ip,Port) (local or remote): one line per
%   agent with its handler, kind and status. A platform that cannot be
%   asked prints the error instead (and the call still succeeds, as in
%   Tartarus). With an unbound argument (or a list), Names are the
%   names of the agents on the current platform.
%
%   @error type_error(link, Link) when Link is neither (Ip,Port), a
%   variable nor a list

list_agents :-
    current_node(Node),
    agent_list(Node, Agents),
    print_agents(Node, Agents).
list_agents(Names) :-
    (   var(Names) ; is_list(Names) ),
    !,
    current_node(Node),
    agent_list(Node, Agents),
    findall(N, member(agent(N, _, _, _), Agents), Names).
list_agents((Ip, Port)) :-
    !,
    must_be(integer, Port),
    catch(remote_agents((Ip, Port), Agents, []), E, true),
    (   var(E)
    ->  print_agents(Ip:Port, Agents)
    ;   message_text(E, Text),
        format("Agents on ~w:~w: cannot list them: ~w~n", [Ip, Port, Text])
    ).
list_agents(Link) :-
    throw(error(type_error(link, Link), context(list_agents/1, _))).

print_agents(Where, Agents) :-
    length(Agents, N),
    format("Agents on ~w (~D):~n", [Where, N]),
    forall(member(agent(A, H, K, S), Agents),
           format("  ~q~t~30| handler ~q~t~50| ~w~t~60| ~w~n", [A, H, K, S])).

list_agent :- list_agents.
list_agent(X) :- list_agents(X).

%!  isexist_agent(?Name, ?Link, ?Handler) is nondet.
%
%   True if agent Name with Handler is on the platform at Link,
%   (Ip,Port), local or remote. With Link unbound the local platform is
%   asked, as in Tartarus, and Link is bound to its (Ip,Port); Name and
%   Handler may be unbound too (then it enumerates).

isexist_agent(Name, Link, Handler) :-
    var(Link),
    !,
    current_node(Node),
    agent_list(Node, Agents),
    get_tartarus_details(Ip, Port),
    Link = (Ip, Port),
    member(agent(Name, Handler, _, _), Agents).
isexist_agent(Name, Link, Handler) :-
    remote_agents(Link, Agents, []),
    (   atom(Name)
    ->  memberchk(agent(Name, Handler, _, _), Agents)
    ;   member(agent(Name, Handler, _, _), Agents)
    ).

%!  save_agent(+Name, +File) is det.

save_agent(Name, File) :-
    current_node(Node),
    agent_save(Node, Name, File).

%!  assert_file_to_tartarus(+File) is det.
%
%   Load an agent program into this running platform. To load one into
%   another node, use load_program_at/3.

assert_file_to_tartarus(File) :-
    load_program(File).

%!  save_tartarus_state(+File) is det.
%!  load_tartarus_state(+File) is det.
%
%   Save every agent of the current platform to File / reinstall them.

save_tartarus_state(File) :-
    current_node(Node),
    node_save_state(Node, File).

load_tartarus_state(File) :-
    current_node(Node),
    node_load_state(Node, File).

%!  agent_hop_times(+Name, -Millis) is det.
%
%   Duration of each hop of agent Name, oldest first (at most the last
%   100), from the start of move_agent at the source to the start of
%   its handler at the destination.

agent_hop_times(Name, Millis) :-
    current_node(Node),
    agent_hop_times(Node, Name, Millis).

%!  agent_hop_statistics(+Name, -Stats) is det.
%
%   Stats is hops{count:N, mean_ms:Mean, median_ms:Median, min_ms:Min,
%   max_ms:Max} over the hops of agent Name (all zero when none).

agent_hop_statistics(Name, hops{count:N, mean_ms:Mean, median_ms:Median,
                                min_ms:Min, max_ms:Max}) :-
    agent_hop_times(Name, Ms),
    length(Ms, N),
    (   N =:= 0
    ->  Mean = 0, Median = 0, Min = 0, Max = 0
    ;   sum_list(Ms, Sum),
        Mean is Sum / N,
        msort(Ms, Sorted),
        Mid is N // 2,
        nth0(Mid, Sorted, Median),
        min_list(Ms, Min),
        max_list(Ms, Max)
    ).
