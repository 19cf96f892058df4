:- module(bounds_output,
          [ output_count_enter/5,       % +Node, +Agent, +Limit, :OnOver, -Saved
            output_count_leave/1        % +Saved
          ]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(library(prolog_stream), [open_prolog_stream/4]).
:- use_module(library(aggregate), [aggregate_all/3]).
:- use_module(library(lists), [append/3]).
:- use_module(bounds_ledger, [window_take/4]).

:- meta_predicate
    output_count_enter(+, +, +, 1, -).

/** <module> Counting the output lines of an agent's call

The bound agent_log_limit(PerMinute) of agent_bounds.pl: during a bounded
call, user_output and user_error are streams of this module that count
the agent's lines (per minute, bounds_ledger.pl) and pass them on to the
streams the call had, until the limit; then the rest is dropped and the
call's OnOver goal is called (agent_bounds.pl stops the call).
*/

:- dynamic
    counters_/2,                % OutStream, ErrStream
    stream_role_/2,             % Stream, out|err
    default_target_/2.          % out|err, Stream

:- thread_local
    budget_/6.                  % Node, Agent, Limit, OnOver, OutTarget, ErrTarget

%!  output_count_enter(+Node, +Agent, +Limit, :OnOver, -Saved) is det.
%
%   Route this thread's user_output, user_error and current output
%   through the counting streams for a call of Agent on Node that may
%   write Limit lines a minute (or `infinite`); call(OnOver, Limit) when
%   it writes more. Saved is for output_count_leave/1.

output_count_enter(Node, Agent, Limit, OnOver, saved(Out0, Err0, Cur0)) :-
    once(stream_property(Out0, alias(user_output))),
    once(stream_property(Err0, alias(user_error))),
    current_output(Cur0),
    counters(Out, Err),
    target(out, Out0, OutTarget),
    target(err, Err0, ErrTarget),
    assertz(budget_(Node, Agent, Limit, OnOver, OutTarget, ErrTarget)),
    set_stream(Out, alias(user_output)),
    set_stream(Err, alias(user_error)),
    set_output(Out).

%!  output_count_leave(+Saved) is det.
%
%   Flush what the call wrote and give the thread back the streams it
%   had before output_count_enter/5.

output_count_leave(saved(Out0, Err0, Cur0)) :-
    counters(Out, Err),
    catch(flush_output(Out), _, true),
    catch(flush_output(Err), _, true),
    retractall(budget_(_, _, _, _, _, _)),
    set_stream(Out0, alias(user_output)),
    set_stream(Err0, alias(user_error)),
    set_output(Cur0).

%   The counting streams: one pair per process, never closed, because a
%   thread created during a bounded call (a pool worker, a connection)
%   inherits its creator's streams and keeps them. Output written through
%   them in a bounded call goes to the call's own user_output or
%   user_error until the agent's lines this minute reach its limit; then
%   it is dropped and the call stopped. Output of a thread that runs no
%   bounded call goes, uncounted, to the streams the process had when
%   the pair was made. A line is a newline, or 4096 characters without
%   one, or one flush of a partial line.
counters(Out, Err) :-
    (   counters_(Out0, Err0)
    ->  Out = Out0,
        Err = Err0
    ;   with_mutex(dfrl_bounds_monitor, make_counters),
        counters_(Out, Err)
    ).

make_counters :-
    (   counters_(_, _)
    ->  true
    ;   once(stream_property(Out0, alias(user_output))),
        once(stream_property(Err0, alias(user_error))),
        assertz(default_target_(out, Out0)),
        assertz(default_target_(err, Err0)),
        open_prolog_stream(bounds_output, write, Out, []),
        open_prolog_stream(bounds_output, write, Err, []),
        set_stream(Out, buffer(line)),
        set_stream(Err, buffer(line)),
        assertz(stream_role_(Out, out)),
        assertz(stream_role_(Err, err)),
        assertz(counters_(Out, Err))
    ).

%   Where a call's output goes: the thread's stream, unless that is a
%   counting stream it inherited.
target(Role, Stream, Target) :-
    (   stream_role_(Stream, _)
    ->  default_target_(Role, Target)
    ;   Target = Stream
    ).

%   Called by the stream layer in the writing thread.
stream_write(S, String) :-
    stream_role_(S, Role),
    (   budget_(Node, Agent, Limit, OnOver, OutTarget, ErrTarget)
    ->  ( Role == out -> Target = OutTarget ; Target = ErrTarget ),
        lines_counted(String, N),
        window_take(log(Node, Agent), Limit, N, Granted),
        (   Granted >= N
        ->  forward(Target, String)
        ;   Granted > 0
        ->  first_lines(String, Granted, Part),
            forward(Target, Part),
            call(OnOver, Limit)
        ;   call(OnOver, Limit)
        )
    ;   default_target_(Role, Target)
    ->  forward(Target, String)
    ;   true
    ).

stream_close(_).

forward(Target, String) :-
    catch(( write(Target, String), flush_output(Target) ), _, true).

lines_counted(String, N) :-
    aggregate_all(count, sub_string(String, _, 1, _, "\n"), NL),
    string_length(String, Len),
    N is max(1, NL) + Len // 4096.

first_lines(String, N, Part) :-
    split_string(String, "\n", "", Lines),
    length(Keep, N),
    (   append(Keep, _, Lines)
    ->  atomic_list_concat(Keep, '\n', Part0),
        atom_concat(Part0, '\n', Part)
    ;   Part = String
    ).
