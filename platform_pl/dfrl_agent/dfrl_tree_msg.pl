:- module(dfrl_tree_msg,
          [ tree_post/4,                % +Address, +Key, +Body, +SkipAfter
            tree_await/7,               % +Node, +Key, +Kind, +Peers, +Probe, -Msgs, -Lost
            tree_wait/6,                % +Node, +Ctx, +Kind, +Peers, -Msgs, -Lost
            tree_poll/6,                % +Node, +Key, +Kinds, +Peers, +Deadline, -Msg
            tree_note/3,                % +Node, +Key, +Body
            tree_forget/2,              % +Node, +Key
            dfrl_tree_msg/3             % +Platform, +Link, +Message (event)
          ]).
:- use_module('../tartarus', [current_node/1, node_property/2, platform_event/1,
                              remote_agents/3]).
:- use_module('../messages', [agent_post/6]).
:- use_module('../agent_bounds', [bounds_park/1]).
:- autoload(library(lists), [append/3, memberchk/2, subtract/3, member/2]).
:- autoload(library(apply), [include/3, exclude/3]).
:- autoload(library(debug), [debug/3]).

/** <module> The messages between the copies of a tree round (dfrl_tree.pl)

A message is posted to the node of the stop its receiver is at, as the
platform event dfrl_tree_msg/3 with msg(Key, Body): Key (a string) names
the round, Body is up(P, Items, Skips, Stats, Name), down(P, Table),
done(P, Skips, Stats), adopt(P, Address, Name) or adopt(P, Address,
Name, Table), P the position of the copy that sends it up or receives
it down (or is adopted by the copy Name at Address, dfrl_tree_adopt.pl). The node keeps it until the copy it is for takes it
(tree_await/7, tree_poll/6). A copy's outcome on its own node
(moved(P, Retries) or failed(P, Text, Retries), dfrl_tree_copies.pl) is
noted directly with tree_note/3; a peer cannot post those.

Peers are kid(Position, Address, Name): the copy at Position on the
node at Address, agent Name (a string), or until(Time) for a copy whose
name is not known (an adopted one), taken for lost after Time. A copy
waits for a message about each peer, and asks a silent peer's node every
probe time whether the peer is still there.
*/

:- dynamic box/3.                       % Node, Key, Body

:- initialization(platform_event(dfrl_tree_msg:dfrl_tree_msg/3)).

%!  dfrl_tree_msg(+Platform, +Link, +Message) is det.
%
%   The platform event of the copies of a tree round: keep Message,
%   msg(Key, Body), on the current node for the copy that waits for it.
%
%   @error domain_error(dfrl_tree_message, Message) for anything else.

dfrl_tree_msg(platform, _Link, msg(Key, Body)) :-
    string(Key),
    ground(Body),
    functor(Body, F, _),
    memberchk(F, [up, down, done, adopt]),
    !,
    current_node(Node),
    assertz(box(Node, Key, Body)).
dfrl_tree_msg(platform, _Link, Message) :-
    throw(error(domain_error(dfrl_tree_message, Message), _)).

%!  tree_note(+Node, +Key, +Body) is det.
%
%   Keep Body on Node for the round Key (a message from this node).

tree_note(Node, Key, Body) :-
    assertz(box(Node, Key, Body)).

%!  tree_forget(+Node, +Key) is det.
%
%   Drop what Node keeps for the round Key (late messages included).

tree_forget(Node, Key) :-
    retractall(box(Node, Key, _)).

%!  tree_post(+Address, +Key, +Body, +SkipAfter) is semidet.
%
%   Post Body for the round Key to the node at Address, with connect and
%   reply timeouts of SkipAfter (at least 0.5 s); fails, with a warning,
%   if it cannot.

tree_post(Address, Key, Body, SkipAfter) :-
    debug(dfrl(tree), 'post to ~w: ~p', [Address, Body]),
    current_node(Node),
    node_property(Node, link(Link)),
    T is max(0.5, SkipAfter),
    catch(agent_post(Address, platform, dfrl_tree_msg, Link, [msg(Key, Body)],
                     [connect_timeout(T), reply_timeout(T)]),
          E,
          ( print_message(warning, E), fail )).

%!  tree_wait(+Node, +Ctx, +Kind, +Peers, -Msgs, -Lost) is det.
%
%   tree_await/7 with the probe of the round Ctx (dfrl_tree.pl): every
%   skip time, until its table timeout and one skip time more.

tree_wait(Node, Ctx, Kind, Peers, Msgs, Lost) :-
    Ctx = ctx(Key, _, _, info(_, _, _, _, _, Timeout, SkipAfter, _)),
    get_time(T0),
    Limit is T0 + Timeout + SkipAfter,
    tree_await(Node, Key, Kind, Peers, probe(SkipAfter, Limit), Msgs, Lost).

%!  tree_await(+Node, +Key, +Kind, +Peers, +Probe, -Msgs, -Lost) is det.
%
%   Wait on Node for a message Kind of the round Key about each of
%   Peers (its first argument is the peer's position), asking the node
%   of a peer every Probe = probe(Seconds, Limit) seconds whether the
%   peer is still there, until the time Limit. Msgs are the messages,
%   Lost the peers that are not there (or did not answer by Limit).

tree_await(Node, Key, Kind, Peers, Probe, Msgs, Lost) :-
    await_loop(Node, Key, Kind, Peers, Probe, [], Msgs, [], Lost).

%   (9 arguments: a wait loop with two accumulator pairs)
await_loop(_, _, _, [], _, Msgs0, Msgs, Lost0, Lost) :-
    !,
    Msgs = Msgs0,
    Lost = Lost0.
await_loop(Node, Key, Kind, Peers, Probe, Msgs0, Msgs, Lost0, Lost) :-
    Probe = probe(Every, Limit),
    get_time(Now),
    Deadline is min(Limit, Now + Every),
    (   tree_poll(Node, Key, [Kind], Peers, Deadline, Msg)
    ->  arg(1, Msg, C),
        exclude(kid_at(C), Peers, Peers1),
        await_loop(Node, Key, Kind, Peers1, Probe, [Msg|Msgs0], Msgs, Lost0, Lost)
    ;   get_time(Now1),
        Now1 >= Limit
    ->  append(Lost0, Peers, Lost), Msgs = Msgs0
    ;   include(gone(Every), Peers, Gone),
        subtract(Peers, Gone, Peers1),
        append(Lost0, Gone, Lost1),
        waiting_long(Key, Kind, Peers1, Probe),
        await_loop(Node, Key, Kind, Peers1, Probe, Msgs0, Msgs, Lost1, Lost)
    ).

%   Say once, ten probe times into a wait, which peers still hold it up
%   (they are there but have not sent their message).
waiting_long(Key, Kind, Peers, probe(Every, Limit)) :-
    (   Peers \== [],
        nb_current(dfrl_tree_waiting, Since-Key-Kind)
    ->  get_time(Now),
        (   Now - Since > 10 * Every,
            \+ nb_current(dfrl_tree_warned, Key-Kind)
        ->  b_setval(dfrl_tree_warned, Key-Kind),
            nb_setval(dfrl_tree_warned, Key-Kind),
            print_message(warning,
                          format("dfrl: tree round ~w: still waiting for ~w from ~p \c
                                  (until ~0f)", [Key, Kind, Peers, Limit]))
        ;   true
        )
    ;   get_time(Now),
        nb_setval(dfrl_tree_waiting, Now-Key-Kind)
    ).

kid_at(C, kid(C, _, _)).

%!  tree_poll(+Node, +Key, +Kinds, +Peers, +Deadline, -Msg) is semidet.
%
%   Msg, of one of Kinds, about one of Peers, as soon as Node has it;
%   fails at the time Deadline. The wait wakes when box/3 changes
%   (thread_wait/2): it was a 5 ms sleep between looks, up to 5 ms a
%   wait, six waits along a round of two levels.

%   The wait is parked (agent_bounds:bounds_park/1): it holds no run
%   slot, and counts against agent_idle_limit, not agent_wall_limit.

tree_poll(Node, Key, Kinds, Peers, Deadline, Msg) :-
    bounds_park(poll(Node, Key, Kinds, Peers, Deadline, Msg)).

poll(Node, Key, Kinds, Peers, Deadline, Msg) :-
    (   member(Kind, Kinds),
        take_msg(Node, Key, Kind, Peers, Msg)
    ->  true
    ;   get_time(Now),
        Now < Deadline,
        thread_wait(has_msg(Node, Key, Kinds, Peers),
                    [deadline(Deadline), wait_preds([box/3])])
    ->  poll(Node, Key, Kinds, Peers, Deadline, Msg)   % (another may take it first)
    ).

has_msg(Node, Key, Kinds, Peers) :-
    box(Node, Key, Msg),
    functor(Msg, Kind, _),
    memberchk(Kind, Kinds),
    arg(1, Msg, C),
    memberchk(kid(C, _, _), Peers),
    !.

take_msg(Node, Key, Kind, Peers, Msg) :-
    box(Node, Key, Msg),
    functor(Msg, Kind, _),
    arg(1, Msg, C),
    memberchk(kid(C, _, _), Peers),
    retract(box(Node, Key, Msg)),
    !.

%   The peer's node does not answer within the probe time, or no longer
%   holds the peer.
gone(_, kid(_, _, until(T))) :-
    !,
    get_time(Now),
    Now > T.
gone(Every, kid(_, Address, Name)) :-
    T is max(0.5, Every),
    atom_string(Agent, Name),
    (   catch(remote_agents(Address, Agents, [connect_timeout(T), reply_timeout(T)]),
              _, fail)
    ->  \+ memberchk(agent(Agent, _, _, _), Agents)
    ;   true
    ).
