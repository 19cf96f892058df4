:- module(messages,
          [ agent_post/5,               % +Address, +Agent, +Handler, +Link, +Args
            agent_post/6,               % +Address, +Agent, +Handler, +Link, +Args, +Options
            platform_event/1,           % +[Module:]Name/Arity
            remote_agents/3,            % +Address, -Agents, +Options
            remote_execute/4            % +Address, +Agent, +Event, +Options
          ]).
:- use_module(node, [current_node/1, node_property/2, node_for_address/2,
                     node_option/3, with_node/2, ctx_node/2,
                     ctx_authenticated/1]).
:- use_module(agents).
:- use_module(worker_pool, [pool_run/3]).
:- use_module(agent_bounds, [bounds_call/4, bounds_post/0, bounds_stopped/3,
                             bounds_warning/2, bounds_peer_post/2]).
:- use_module(transport).
:- use_module(code_safety, [check_post/3]).
:- autoload(library(error), [must_be/2, existence_error/2]).
:- autoload(library(option), [option/2]).
:- autoload(library(lists), [append/3]).

/** <module> Messages to agents and to declared platform events

A posted message names an agent and its handler: the receiving platform
calls Handler(Agent, Link, Args...) in the agent's module, in a fresh
thread, and only if Agent is registered there with that handler and
declares that event (code_safety:check_post/3): it is in the agent's
events(List) (agent_create/4), or, for an agent that declares none, the
agent's own module defines Handler with that arity. A node
may also declare platform events (platform_event/1): posting to the
pseudo-agent `platform` calls Module:Handler(platform, Link, Args...) if
Module:Handler/N was declared (Module `user` unless the declaration
names one). Nothing else can be called by a peer, and a remote peer may
post only if it proved one of the node's tokens (or the node is open):
`post` is one of the requests node:requires_authentication/1 names.
*/

:- dynamic declared_event/1.

:- multifile node:platform_request/4.

%!  platform_event(+NameArity) is det.
%
%   Declare Module:Name/Arity (Arity >= 2; Module defaults to `user`) as
%   a platform event that peers may trigger with a posted message to the
%   pseudo-agent `platform`: a message [Name, platform, Link | Args] with
%   Arity-2 Args calls Module:Name(platform, Link, Args...). Peers name
%   only Name; one Name/Arity is served by one module (the first
%   declared).
%
%   @error type_error(predicate_indicator, NameArity)

platform_event(Spec) :-
    (   Spec = Module:Name/Arity
    ->  true
    ;   Spec = Name/Arity
    ->  Module = user
    ;   throw(error(type_error(predicate_indicator, Spec), _))
    ),
    must_be(atom, Module),
    must_be(atom, Name),
    must_be(integer, Arity),
    (   declared_event(_:Name/Arity)
    ->  true
    ;   assertz(declared_event(Module:Name/Arity))
    ).

%!  agent_post(+Address, +Agent, +Handler, +Link, +Args) is det.
%
%   Post a message to Agent at the platform at Address: the platform
%   calls Handler(Agent, Link, Args...) there, in a new thread. Succeeds
%   once the platform accepted the message.
%
%   @error existence_error(agent, Agent) if the platform does not host
%   Agent with Handler (nor declares Handler as a platform event).
%   @error permission_error(post, event, Handler/Arity) if Agent does
%   not declare that event.

agent_post(Address, Agent, Handler, Link, Args) :-
    agent_post(Address, Agent, Handler, Link, Args, []).

%!  agent_post(+Address, +Agent, +Handler, +Link, +Args, +Options) is det.
%
%   As agent_post/5. Options: tokens(List), the tokens to prove to a
%   remote platform (default: the current node's), connect_timeout(S),
%   reply_timeout(S), kind(Kind) (transport_request/4; default `auto`:
%   a binary frame once the tokens are proved, so that a message that
%   carries packed vectors, e.g. the tables of a tree round, is not
%   escaped and parsed as text). For a process without a node of its
%   own (a shell command sending a control event).
%
%   @error permission_error(access, platform, Address) if the remote
%   platform accepts none of the tokens.

agent_post(Address0, Agent, Handler, Link, Args, Options) :-
    must_be(atom, Handler),
    must_be(list, Args),
    must_be(list, Options),
    bounds_post,
    address_normalize(Address0, Address),
    (   node_for_address(Address, Node)
    ->  deliver(Node, Agent, Handler, Link, Args)
    ;   request_options(Defaults),
        append(Options, Defaults, Options1),
        transport_request(Address, post(Agent, Handler, Link, Args), _, Options1)
    ).

request_options([connect_timeout(CT), reply_timeout(RT), kind(auto)]) :-
    (   catch(current_node(Node), _, fail)
    ->  node_option(Node, connect_timeout, CT),
        node_option(Node, reply_timeout, RT)
    ;   CT = 5,
        RT = 30
    ).

deliver(Node, Agent, Handler, Link, Args) :-
    max_running_posts(Max),
    Goal0 =.. [Handler, Agent, Link | Args],
    (   agent_property(Node, Agent, handler(Handler))
    ->  check_post(Node, Agent, Goal0),
        agent_module(Node, Agent, M),
        Goal = M:Goal0
    ;   Agent == platform,
        length(Args, N),
        Arity is N + 2,
        declared_event(Module:Handler/Arity)
    ->  Goal = Module:Goal0
    ;   existence_error(agent, Agent)
    ),
    pool_run(messages, run_message(Node, Agent, Goal), [max(Max)]).

%   At most this many posted events run (or wait for a running slot of
%   agent_bounds.pl) at once in a process: a flood of posts from agents
%   made a thread per post (536 in a hostile-bench run). A post over it
%   is refused with resource_error(workers(messages)).
max_running_posts(64).

%   An agent's event runs within its bounds (agent_bounds.pl), a platform
%   event (the node's own code) without.
run_message(Node, Agent, Goal) :-
    catch(with_node(Node, bounded_event(Node, Agent, Goal)), E,
          message_error(Node, Agent, E)).

bounded_event(Node, Agent, M:Goal) :-
    (   Agent == platform
    ->  ( call(M:Goal) -> true ; true )
    ;   bounds_call(Node, Agent, M, ( call(M:Goal) -> true ; true ))
    ).

message_error(Node, Agent, '$dfrl_bound'(Kind)) :-
    !,
    bounds_stopped(Node, Agent, Kind),
    catch(agent_purge(Node, Agent), _, true).
message_error(Node, Agent, E) :-
    bounds_warning(Node, dfrl(agent_crashed(Node, Agent, E))).

%!  remote_agents(+Address, -Agents, +Options) is det.
%
%   Agents (agent(Name, Handler, Kind, Status)) on the platform at
%   Address, local or remote.

remote_agents(Address0, Agents, Options) :-
    address_normalize(Address0, Address),
    (   node_for_address(Address, Node)
    ->  agent_list(Node, Agents)
    ;   transport_request(Address, agents, Agents, Options)
    ).

%!  remote_execute(+Address, +Agent, +Event, +Options) is det.
%
%   Start Agent on the platform at Address with Event. A remote platform
%   requires a proof of one of its tokens (option tokens(List), default
%   the current node's tokens).

remote_execute(Address0, Agent, Event, Options) :-
    address_normalize(Address0, Address),
    (   node_for_address(Address, Node)
    ->  node_property(Node, link(Link)),
        agent_execute(Node, Agent, Link, Event)
    ;   (   option(tokens(_), Options)
        ->  Options1 = Options
        ;   catch(current_node(Here), _, fail),
            node_property(Here, tokens(Tokens))
        ->  Options1 = [tokens(Tokens)|Options]
        ;   Options1 = [tokens([])|Options]
        ),
        transport_request(Address, execute(Agent, Event), _,
                          [action(execute)|Options1])
    ).

%   A peer delivers at most peer_post_limit(N) posts a minute
%   (agent_bounds:bounds_peer_post/2); more are refused with
%   resource_error(posts) before anything of them is looked at.
node:platform_request(post(Agent, Handler, Link, Args), Ctx, ok(delivered),
                      true) :-
    ctx_node(Ctx, Node),
    bounds_peer_post(Ctx, Link),
    must_be(atom, Handler),
    must_be(list, Args),
    deliver(Node, Agent, Handler, Link, Args).
node:platform_request(agents, Ctx, ok(Agents), true) :-
    ctx_node(Ctx, Node),
    agent_list(Node, Agents).
node:platform_request(execute(Agent, Event), Ctx, Reply, true) :-
    ctx_node(Ctx, Node),
    (   ctx_authenticated(Ctx)
    ->  node_property(Node, link(Link)),
        agent_execute(Node, Agent, Link, Event),
        Reply = ok(started)
    ;   node_property(Node, address(Here)),
        Reply = error(error(permission_error(execute, platform, Here), _))
    ).
