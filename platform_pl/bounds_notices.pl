:- module(bounds_notices,
          [ bounds_arrived/3,           % +Node, +Agent, +Source
            bounds_notify_source/3,     % +Node, +Agent, +Kind
            agent_bound_report/3        % ?Node, ?Agent, ?Report
          ]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(library(aggregate), [aggregate_all/3]).
:- use_module(library(debug), [debug/3]).
:- use_module(node,
              [ node_property/2, node_option/3, node_for_address/2, with_node/2,
                ctx_node/2, ctx_peer/2 ]).
:- use_module(transport, [transport_request/4]).
:- use_module(worker_pool, [pool_run/3]).
:- use_module(bounds_ledger, [window_take/4, bounds_warning/2]).

/** <module> Notices of agents stopped by their bounds

When a node stops an agent for going over a bound (agent_bounds.pl), it
tells the node the agent came from, the source of its last transfer,
with the request bound_notice(Agent, Kind, Here). That node checks the
notice for shape and size, records it (agent_bound_report/3: the last
100 per node) and prints it: a notice can only ever become such a record
and a warning line. At most 60 notices per node and minute are sent.
*/

:- dynamic
    arrived_/3,                 % Node, Agent, Source
    report_/4,                  % Node, Agent, Time, Report
    notice_/4,                  % Node, Agent, Kind, Source: to be sent
    notice_senders_/1.          % Count: senders draining notice_/4

:- multifile
    node:platform_request/4,
    node:requires_authentication/1,
    node:node_stopping/1,
    agents:agent_changed/3.

max_notices_per_minute(60).
max_reports_kept(100).

%!  bounds_arrived(+Node, +Agent, +Source) is det.
%
%   Agent arrived on Node from the node at address Source: that node is
%   told if Agent is stopped here.

bounds_arrived(Node, Agent, Source) :-
    retractall(arrived_(Node, Agent, _)),
    assertz(arrived_(Node, Agent, Source)).

%!  bounds_notify_source(+Node, +Agent, +Kind) is det.
%
%   Agent was stopped on Node for going over bound Kind: tell the node
%   it came from (bounds_arrived/3), if it came from one. The notice is
%   sent from a pool thread; this returns at once.

bounds_notify_source(Node, Agent, Kind) :-
    (   arrived_(Node, Agent, Source)
    ->  notify(Node, Agent, Kind, Source)
    ;   true
    ).

%   Notices wait in a list (at most 60 per node and minute are taken,
%   so it stays short) that at most two senders of the pool
%   dfrl_bound_notices drain. A notice is never dropped because the
%   senders are busy: when eight agents are stopped at once, the sender
%   already running takes the ones it finds (with two pool workers and
%   no list, the third notice was refused by the pool and lost). The
%   count of running senders and the list change under one mutex, so a
%   sender cannot leave while a notice it did not see waits.
notify(Node, Agent, Kind, Source) :-
    max_notices_per_minute(Max),
    window_take(notices(Node), Max, 1, Granted),
    (   Granted =:= 1
    ->  with_mutex(dfrl_bound_notices,
                   ( assertz(notice_(Node, Agent, Kind, Source)),
                     (   notice_senders_(N), N >= 2
                     ->  Start = false
                     ;   change_senders(1),
                         Start = true
                     ) )),
        (   Start == true
        ->  catch(pool_run(dfrl_bound_notices, send_notices, [max(8)]), E,
                  ( with_mutex(dfrl_bound_notices, change_senders(-1)),
                    debug(dfrl(bounds), 'notice sender not started: ~p', [E]) ))
        ;   true
        )
    ;   true
    ).

send_notices :-
    with_mutex(dfrl_bound_notices,
               (   retract(notice_(Node, Agent, Kind, Source))
               ->  Next = notice(Node, Agent, Kind, Source)
               ;   change_senders(-1),
                   Next = none
               )),
    (   Next = notice(Node, Agent, Kind, Source)
    ->  catch(send_notice(Node, Agent, Kind, Source), E,
              debug(dfrl(bounds), 'notice of ~p: ~p', [Agent, E])),
        send_notices
    ;   true
    ).

change_senders(Delta) :-
    (   retract(notice_senders_(N0)) -> true ; N0 = 0 ),
    N is N0 + Delta,
    assertz(notice_senders_(N)).

send_notice(Node, Agent, Kind, Source) :-
    node_property(Node, address(Here)),
    (   node_for_address(Source, Local)
    ->  record_report(Local, Agent, Kind, Here, local)
    ;   node_property(Node, tokens(Tokens)),
        node_option(Node, connect_timeout, CT),
        catch(with_node(Node,
                        transport_request(Source, bound_notice(Agent, Kind, Here), _,
                                          [ tokens(Tokens), connect_timeout(CT),
                                            reply_timeout(CT) ])),
              E, debug(dfrl(bounds), 'notice to ~p: ~p', [Source, E]))
    ).

node:requires_authentication(bound_notice(_, _, _)).

node:platform_request(bound_notice(Agent, Kind, From), Ctx, ok(noted), true) :-
    ctx_node(Ctx, Node),
    (   valid_notice(Agent, Kind, From)
    ->  true
    ;   throw(error(domain_error(bound_notice, bound_notice/3), _))
    ),
    (   ctx_peer(Ctx, Peer) -> true ; Peer = unknown ),
    record_report(Node, Agent, Kind, From, Peer).

%   A notice holds an agent name, a bound and an address, of bounded
%   size; nothing else is accepted.
valid_notice(Agent, Kind, Host:Port) :-
    atom(Agent), atom_length(Agent, AL), AL =< 256,
    compound(Kind), compound_name_arity(Kind, K, 1),
    memberchk(K, [cpu, memory, module_memory, memory_budget, posts, log,
                  text_size, integer_size, wall, idle]),
    arg(1, Kind, Limit),
    ( number(Limit) ; Limit == infinite ),
    atomic(Host), \+ number(Host), atom_length(Host, HL), HL =< 256,
    integer(Port), between(0, 65535, Port).

record_report(Node, Agent, Kind, From, Peer) :-
    get_time(Now),
    Report = bound(Kind, From, Peer),
    with_mutex(dfrl_bounds,
               ( assertz(report_(Node, Agent, Now, Report)),
                 prune_reports(Node) )),
    bounds_warning(Node, dfrl_bounds(report(Node, Agent, Kind, From))).

prune_reports(Node) :-
    max_reports_kept(Max),
    aggregate_all(count, report_(Node, _, _, _), N),
    (   N > Max,
        retract(report_(Node, _, _, _))
    ->  prune_reports(Node)
    ;   true
    ).

%!  agent_bound_report(?Node, ?Agent, ?Report) is nondet.
%
%   Node was told that its Agent was stopped elsewhere for going over a
%   bound. Report is bound(Kind, From, Peer, Time): Kind as in
%   '$dfrl_bound'(Kind), From the address the stopping node gave, Peer
%   the connection's peer (`local` for a node of this process), Time
%   when it was told. The last 100 per node are kept.

agent_bound_report(Node, Agent, bound(Kind, From, Peer, Time)) :-
    report_(Node, Agent, Time, bound(Kind, From, Peer)).

agents:agent_changed(removed, Node, Agent) :-
    retractall(arrived_(Node, Agent, _)).

node:node_stopping(Node) :-
    retractall(arrived_(Node, _, _)),
    with_mutex(dfrl_bound_notices, retractall(notice_(Node, _, _, _))),
    retractall(report_(Node, _, _, _)).
