:- module(bridge_registry,
          [ bridge_register_robot/2,    % +Robot, +Props
            bridge_unregister_robot/1,  % +Robot
            bridge_robot/2,             % ?Robot, ?Props
            bridge_forget_robots/0,
            registered/1,               % +Robot
            offers/2,                   % +Kind, +Robot
            check_shape/1,              % +Shape
            layout_size/2,              % +Layout, -N
            bridge_set_codec/1,         % +Codec
            bridge_codec/1              % -Codec
          ]).
:- use_module(bridge_queue, [ensure_request_queue/0]).
:- autoload(library(error), [must_be/2, domain_error/2, existence_error/2]).
:- autoload(library(lists), [member/2]).
:- autoload(library(apply), [foldl/4, maplist/2]).
:- autoload(library(debug), [debug/3]).

/** <module> The bridge's robots and codec

Which robots this process hosts and what each offers (a Q-table of a
shape, a parameter vector of a layout), and the codec values travel in
between agent threads and the host: the state the bridge's table and
parameter API (bridge_tables.pl) checks a request against. Part of the
bridge, robot_bridge.pl, which exports all of it.
*/

:- dynamic
    robot_/2,                   % Robot, Props
    codec_/1.                   % fts | text

codec_(text).

%!  bridge_register_robot(+Robot, +Props) is det.
%
%   Register a robot hosted by this process, replacing an earlier
%   registration of the same robot. Robot is an atom or an integer. Props
%   is a list that says what the robot offers: shape([NStates, NActions])
%   for a Q-table, layout(Layout) for a parameter vector (at least one of
%   them), and usually algo(Name) and learner(tabular|function), e.g.
%   `[algo(qlearning), shape([64, 4]), learner(tabular)]` or
%   `[algo(dqn), learner(function), layout([w1-[4,16], b1-[16]])]`.
%
%   @error type_error(list, Props)
%   @error domain_error(robot_props, Props) without shape/1 or layout/1.
%   @error domain_error(shape([nstates, nactions]), Shape) for a bad shape.
%   @error domain_error(param_layout, Layout) for a bad layout.

bridge_register_robot(Robot, Props) :-
    must_be(atomic, Robot),
    must_be(list, Props),
    (   memberchk(shape(Shape), Props)
    ->  check_shape(Shape)
    ;   memberchk(layout(_), Props)
    ->  true
    ;   domain_error(robot_props, Props)
    ),
    (   memberchk(layout(Layout), Props)
    ->  layout_size(Layout, _)
    ;   true
    ),
    ensure_request_queue,
    with_mutex(robot_bridge,
               ( retractall(robot_(Robot, _)),
                 assertz(robot_(Robot, Props)) )),
    debug(robot_bridge, 'registered robot ~q ~q', [Robot, Props]).

%!  bridge_unregister_robot(+Robot) is det.
%
%   Forget Robot. Requests already queued for it are answered with
%   existence_error(robot, Robot) when the host serves them. Succeeds
%   silently if Robot was not registered.

bridge_unregister_robot(Robot) :-
    must_be(atomic, Robot),
    with_mutex(robot_bridge, retractall(robot_(Robot, _))).

%!  bridge_robot(?Robot, ?Props) is nondet.
%
%   True when Robot is registered in this process with Props.

bridge_robot(Robot, Props) :-
    robot_(Robot, Props).

%!  bridge_forget_robots is det.
%
%   Forget every robot (robot_bridge:bridge_shutdown/0).

bridge_forget_robots :-
    retractall(robot_(_, _)).

%!  registered(+Robot) is det.
%
%   @error existence_error(robot, Robot) if Robot is not registered here.

registered(Robot) :-
    (   robot_(Robot, _)
    ->  true
    ;   existence_error(robot, Robot)
    ).

%!  offers(+Kind, +Robot) is det.
%
%   Robot offers a Q-table (Kind table) or a parameter vector (Kind
%   params).
%
%   @error existence_error(qtable, Robot), existence_error(params, Robot)

offers(table, Robot) :-
    (   robot_(Robot, Props),
        memberchk(shape(_), Props)
    ->  true
    ;   throw(error(existence_error(qtable, Robot),
                    context(_, 'the robot offers parameters, no Q-table (a function learner)')))
    ).
offers(params, Robot) :-
    (   robot_(Robot, Props),
        memberchk(layout(_), Props)
    ->  true
    ;   throw(error(existence_error(params, Robot),
                    context(_, 'the robot offers a Q-table, no parameter vector')))
    ).

%!  layout_size(+Layout, -N) is det.
%
%   N floats in a vector of Layout.
%
%   @error domain_error(param_layout, Layout) for a bad layout.

layout_size(Layout, N) :-
    (   is_list(Layout),
        Layout \== [],
        maplist(layout_block, Layout),
        foldl(add_block, Layout, 0, N),
        N > 0
    ->  true
    ;   domain_error(param_layout, Layout)
    ).

layout_block(Name-Dims) :-
    atom(Name),
    is_list(Dims),
    forall(member(D, Dims), ( integer(D), D >= 0 )).

add_block(_-Dims, N0, N) :-
    foldl(mul_dim, Dims, 1, P),
    N is N0 + P.

mul_dim(D, P0, P) :-
    P is P0*D.

%!  check_shape(+Shape) is det.
%
%   @error domain_error(shape([nstates, nactions]), Shape) for a bad shape.

check_shape(Shape) :-
    (   Shape = [NS, NA],
        integer(NS), NS > 0,
        integer(NA), NA > 0
    ->  true
    ;   domain_error(shape([nstates, nactions]), Shape)
    ).

%!  bridge_set_codec(+Codec) is det.
%
%   Select how values travel between agents and the host: `fts`
%   (fast_term_serialized/2 bytes) or `text`. The host sets `fts` only
%   after its start-up self-test passed.

bridge_set_codec(Codec) :-
    must_be(oneof([fts, text]), Codec),
    with_mutex(robot_bridge,
               ( retractall(codec_(_)),
                 assertz(codec_(Codec)) )).

%!  bridge_codec(-Codec) is det.
%
%   Codec is the value codec in use (`fts` or `text`).

bridge_codec(Codec) :-
    codec_(Codec), !.

